"""Presser foot of the sewing machine (issue 5; seed 000 ch. 12): spring preload and lifting force.

The feed dog's point Q (= Z of the scene `sewing-feed`, optimized design l2 = 2.0, l22 = 1.0 mm,
gamma = -10 deg, omega = 575 rad/s) lifts the presser foot (mass m, spring c, preload y0) over the
working stroke, points 1 -> 2 -> 3 of its path. The vertical acceleration a_y of Q comes from the
solved kinematics (exact, by AD), not from the seed's Table 12.1. With d'Alembert's principle for
the foot (lifted by Δy above its rest), the force between feed dog and foot is

    F_z = m (g + a_y) + c (y0 + Δy)                                     (a_y up-positive)

and contact needs F_z ≥ 0. The seed writes this at three points (eq. 12.3, 12.6, 12.9):

    F_z1 = m g + c y0                  (point 1, 195°: start of the stroke; a_y1 neglected)
    F_z2a = m g + c (y0 + b) − m a_2   (point 2, the top of the path: a_2 = 424.45 m/s² downwards)
    F_z3 = m g + c y0 − m a_3          (point 3, 385°: Q goes under the plate; a_3 = 30.83 m/s²)

and sizes the preload from F_z2a ≥ 0:  y0 > (m a_2 − m g)/c − b  (eq. 12.11).

    python experiments/presser_foot.py [--step DEG]
"""

from __future__ import annotations

import argparse

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from jaxlink import load, solve, time_derivatives, transfer  # noqa: E402

# seed 000 ch. 12
C_SPRING = 3100.0  # N/m, spring stiffness (manufacturer)
MASS = 0.024  # kg, needle bar + presser foot (weighed)
G = 9.81  # m/s²
B_SEED = 1.3e-3  # m, the design limit "výška posuvu b = 0.0013 m" the seed used in (12.11)
B_ACTUAL = 1.13e-3  # m, the foot's lift at point 2 given in the seed ("v bode 2: b = 0,00113 m")
Y0_CHOSEN = 2.0e-3  # m, the seed's chosen preload
POINTS_DEG = {1: 195.0, 2: 295.0, 3: 385.0}  # the seed's points 1, 2, 3 (crank angle)
OMEGA = 575.0
DESIGN = dict(l2=2.0, l22=1.0, gamma=-10.0)


def feed_point(step_deg: float = 5.0, omega: float = OMEGA) -> dict:
    """Crank angles (deg, from 75° as the seed's tables), height y (m) and vertical velocity and
    acceleration (m/s, m/s²) of the feed point Z of the optimized design at constant ω."""
    mech = load("sewing-feed", overrides=DESIGN)
    deg = 75.0 + step_deg * np.arange(int(round(360.0 / step_deg)) + 1)
    phis = np.deg2rad(deg)
    sol = solve(mech, phis)
    assert np.all(np.asarray(sol.converged))
    tr = transfer(mech, jnp.asarray(phis), sol.q, jnp.asarray(mech.parameters), order=2)
    _, _, v, a = time_derivatives(tr, omega)
    k = mech.point_names.index("Z")
    return {"deg": deg, "y": np.asarray(tr.points[:, k, 1]), "vy": np.asarray(v[:, k, 1]),
            "ay": np.asarray(a[:, k, 1])}


def at(kin: dict, deg: float, key: str) -> float:
    i = int(np.argmin(np.abs(kin["deg"] - deg)))
    assert abs(kin["deg"][i] - deg) < 1e-9, f"{deg}° is not on the grid"
    return float(kin[key][i])


def preload_bound(a_down: float, b: float, *, m: float = MASS, c: float = C_SPRING, g: float = G) -> float:
    """Seed eq. (12.11): the least preload y0 (m) keeping contact at the top of the path, where the
    foot is lifted by b and Q accelerates downwards at a_down (m/s², positive)."""
    return (m * a_down - m * g) / c - b


def seed_lifting_forces(y0: float, b: float, a2_down: float, a3: float, *, m: float = MASS, c: float = C_SPRING,
                        g: float = G) -> tuple[float, float, float]:
    """Seed eq. (12.3), (12.6), (12.9): F_z1, F_z2a, F_z3 in N, exactly as the seed writes them."""
    return m * g + c * y0, m * g + c * (y0 + b) - m * a2_down, m * g + c * y0 - m * a3


def contact_force(ay, lift, y0: float, *, m: float = MASS, c: float = C_SPRING, g: float = G):
    """The consistent d'Alembert form: F_z = m (g + a_y) + c (y0 + Δy) (a_y up-positive), N."""
    return m * (g + np.asarray(ay)) + c * (y0 + np.asarray(lift))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--step", type=float, default=5.0, help="crank step in degrees (default 5, the seed's grid)")
    args = ap.parse_args()
    kin = feed_point(args.step)
    y1, ay1 = at(kin, POINTS_DEG[1], "y"), at(kin, POINTS_DEG[1], "ay")
    y2, ay2 = at(kin, POINTS_DEG[2], "y"), at(kin, POINTS_DEG[2], "ay")
    ay3 = at(kin, POINTS_DEG[3], "ay")
    ymax_i = int(np.argmax(kin["y"]))
    print(f"Feed point Q of the optimized design (l2 2.0, l22 1.0 mm, gamma -10°) at ω = {OMEGA:g} rad/s, "
          f"from jaxlink's kinematics ({args.step:g}° grid):")
    print(f"  point 1 ({POINTS_DEG[1]:g}°): y = {1e3 * y1:.3f} mm, a_y = {ay1:+.3f} m/s²   (seed: 56.5 mm, 15.47)")
    print(f"  point 2 ({POINTS_DEG[2]:g}°): y = {1e3 * y2:.3f} mm, a_y = {ay2:+.3f} m/s²   (seed: 57.9 mm, "
          "+424.45: a sign typo, the acceleration is downwards)")
    print(f"  point 3 ({POINTS_DEG[3]:g}°): a_y = {ay3:+.3f} m/s²   (seed: 30.83)")
    print(f"  the true top of the path is at {kin['deg'][ymax_i]:g}°: y = {1e3 * kin['y'][ymax_i]:.3f} mm, "
          f"a_y = {kin['ay'][ymax_i]:+.2f} m/s²; rise from point 1 = {1e3 * (kin['y'][ymax_i] - y1):.3f} mm")

    a2 = -ay2  # downwards, positive
    print(f"\nMinimum preload, seed eq. (12.11), y0 > (m a_2 − m g)/c − b with a_2 = {a2:.2f} m/s²:")
    for label, b in (("the seed's b = 1.3 mm (design limit)", B_SEED), ("the actual b = 1.13 mm", B_ACTUAL)):
        print(f"  {label:<38}: y0 > {1e3 * preload_bound(a2, b):.3f} mm")
    print("  (the seed prints y0 > 1.9 mm: it used b = 1.3 mm; with the actual 1.13 mm its chosen y0 = 2.0 mm "
          "is short)")

    f1, f2a, f3 = seed_lifting_forces(Y0_CHOSEN, B_ACTUAL, a2, ay3)
    print(f"\nLifting force with y0 = {1e3 * Y0_CHOSEN:g} mm, seed's formulas (12.3), (12.6), (12.9):")
    print(f"  F_z1  = m g + c y0               = {f1:.4f} N   (seed 6.435)")
    print(f"  F_z2a = m g + c (y0 + b) − m a_2 = {f2a:+.4f} N  (seed: 0 by assumption; < 0 means the foot lifts off)")
    print(f"  F_z3  = m g + c y0 − m a_3       = {f3:.5f} N  (seed 5.696; its rounded a_3 = 30.83 gives "
          f"{seed_lifting_forces(Y0_CHOSEN, B_ACTUAL, a2, 30.83)[2]:.5f})")

    # the consistent form over the whole working stroke: Δy = y − y(point 1), clipped at 0 (below the plate)
    sel = (kin["deg"] >= POINTS_DEG[1] - 1e-9) & (kin["deg"] <= POINTS_DEG[3] + 1e-9)
    lift = np.clip(kin["y"][sel] - y1, 0.0, None)
    fz = contact_force(kin["ay"][sel], lift, Y0_CHOSEN)
    need = np.max(-(MASS * (G + kin["ay"][sel])) / C_SPRING - lift)
    print("\nConsistent d'Alembert form F_z = m (g + a_y) + c (y0 + Δy), Δy = y − y_1 (a_y up-positive):")
    print(f"  point 1: {contact_force(ay1, 0.0, Y0_CHOSEN):.4f} N (the seed leaves out m a_y1 = {MASS * ay1:.3f} N)")
    print(f"  point 3: {contact_force(ay3, 0.0, Y0_CHOSEN):.4f} N (the seed subtracts m a_3 although Q accelerates "
          "upwards there: it keeps point 2's downward sign)")
    print(f"  min F_z over points 1-3: {fz.min():+.4f} N at {kin['deg'][sel][int(np.argmin(fz))]:g}°; "
          f"contact all along needs y0 ≥ {1e3 * need:.3f} mm")


if __name__ == "__main__":
    main()
