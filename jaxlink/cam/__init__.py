"""Stiff cam-follower dynamics of the knitting sinker (project issue 6).

The sinker of a small circular knitting machine slides in a groove of the needle cylinder;
its butt is lifted by a stationary stitch cam. This package rebuilds the seed's model
(eq. 4.25: contact through a spring `C`, friction, damping from the log decrement), the six
cam tracks, a hybrid explicit/implicit JAX integrator that locates every contact loss, and
the static and dynamic jamming thresholds. See `docs/sinker.md`.
"""

from .track import (
    CamGeometry as CamGeometry,
    CamTrack as CamTrack,
    butt_speed as butt_speed,
    cam_eval as cam_eval,
    cam_profile as cam_profile,
    cam_segment as cam_segment,
    make_cam as make_cam,
    seed_geometries as seed_geometries,
)
from .integrate import (
    RESULTS as RESULTS,
    DormandPrince5 as DormandPrince5,
    RadauIIA5 as RadauIIA5,
    Solution as Solution,
    Stats as Stats,
    integrate_hybrid as integrate_hybrid,
)
from .jamming import (
    Thresholds as Thresholds,
    jammed_at as jammed_at,
    thresholds as thresholds,
)
from .sinker import (
    SinkerParams as SinkerParams,
    acceleration as acceleration,
    damping_from_log_decrement as damping_from_log_decrement,
    drive_fraction as drive_fraction,
    lag as lag,
    make_params as make_params,
    nonsmooth_acceleration as nonsmooth_acceleration,
    p_coefficients as p_coefficients,
    static_threshold as static_threshold,
    vector_field as vector_field,
)
from .simulate import (
    AUTO_IMPLICIT_ABOVE as AUTO_IMPLICIT_ABOVE,
    Maxima as Maxima,
    SinkerSolution as SinkerSolution,
    auto_method as auto_method,
    maxima as maxima,
    product_cases as product_cases,
    simulate as simulate,
    simulate_batch as simulate_batch,
)
