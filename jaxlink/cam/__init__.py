"""Stiff cam-follower dynamics; the knitting sinker is its scene.

The sinker of a small circular knitting machine slides in a groove of the needle cylinder;
its butt is lifted by a stationary stitch cam. This package rebuilds the model of a
knitting-machine thesis (contact through a spring `C`, friction, damping from the logarithmic
decrement; equations in docs/methods/sinker.md), the six cam tracks, a hybrid explicit/implicit
JAX integrator that locates every contact loss, and the static and dynamic jamming thresholds.
Measured results: docs/studies/sinker.md; the integrators measured against diffrax:
docs/methods/cam-integrators.md.
"""

from .integrate import RESULTS as RESULTS
from .integrate import DormandPrince5 as DormandPrince5
from .integrate import RadauIIA5 as RadauIIA5
from .integrate import Solution as Solution
from .integrate import Stats as Stats
from .integrate import integrate_hybrid as integrate_hybrid
from .jamming import Thresholds as Thresholds
from .jamming import jammed_at as jammed_at
from .jamming import thresholds as thresholds
from .reference import reference_solution as reference_solution
from .simulate import AUTO_IMPLICIT_ABOVE as AUTO_IMPLICIT_ABOVE
from .simulate import Maxima as Maxima
from .simulate import SinkerSolution as SinkerSolution
from .simulate import auto_method as auto_method
from .simulate import maxima as maxima
from .simulate import product_cases as product_cases
from .simulate import simulate as simulate
from .simulate import simulate_batch as simulate_batch
from .sinker import SinkerParams as SinkerParams
from .sinker import acceleration as acceleration
from .sinker import damping_from_log_decrement as damping_from_log_decrement
from .sinker import drive_fraction as drive_fraction
from .sinker import lag as lag
from .sinker import make_params as make_params
from .sinker import nonsmooth_acceleration as nonsmooth_acceleration
from .sinker import p_coefficients as p_coefficients
from .sinker import static_threshold as static_threshold
from .sinker import vector_field as vector_field
from .track import CamGeometry as CamGeometry
from .track import CamTrack as CamTrack
from .track import butt_speed as butt_speed
from .track import cam_eval as cam_eval
from .track import cam_profile as cam_profile
from .track import cam_segment as cam_segment
from .track import make_cam as make_cam
from .track import seed_geometries as seed_geometries
