"""An independent numpy model of the sewing-feed six-bar (shared/spec/feed-six-bar.md, not
jaxlink's solver): the position by two circle intersections (closed form), the feed-dog point Z,
and its travel along x (max − min over the turn) located between the samples by Newton on x′(φ)
with x′ by the complex step (exact) and x″ by a central difference of it. Lengths in mm.

    B = l2 e(φ), E = (l8, l7), D on |D − B| = l3, |D − E| = l44, F = D + l4 (E − D) / l44,
    C = −l22 e(φ + γ), H on |H − F| = l6, |H − C| = l5, Z = F + (l6 + l66) (H − F) / l6.
"""

import numpy as np

NAMES = ("l2", "l22", "gamma", "l3", "l4", "l44", "l5", "l6", "l66", "l7", "l8")
NOMINAL = dict(l2=13.0, l22=9.0, gamma=100.0, l3=60.0, l4=42.0, l44=21.0, l5=57.0, l6=48.0, l66=16.5, l7=36.0,
               l8=56.0)


def _circles(a, ra, b, rb, side):
    """The intersection of |X − a| = ra and |X − b| = rb on `side` (±1) of a → b (complex-safe)."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    d2 = dx * dx + dy * dy
    d = np.sqrt(d2)
    t = (ra * ra - rb * rb + d2) / (2.0 * d)
    h = np.sqrt(ra * ra - t * t)
    ux, uy = dx / d, dy / d
    return a[0] + t * ux - side * h * uy, a[1] + t * uy + side * h * ux


# the branches of the file's start (φ = 75°: φ3 = 2.5°, φ4 = 105°, φ5 = 276°, φ6 = 178.5°)
SIDES = (-1.0, -1.0)


def z(p, phi, sides=SIDES):
    """(x, y) of Z (mm) for parameters `p` (a dict of arrays, mm and degrees) at inputs `phi` (rad,
    broadcast with the parameters; complex allowed)."""
    g = np.radians(p["gamma"])
    b = (p["l2"] * np.cos(phi), p["l2"] * np.sin(phi))
    e = (p["l8"] + 0.0 * phi, p["l7"] + 0.0 * phi)
    d = _circles(b, p["l3"], e, p["l44"], sides[0])
    f = tuple(di + p["l4"] * (ei - di) / p["l44"] for di, ei in zip(d, e))
    c = (-p["l22"] * np.cos(phi + g), -p["l22"] * np.sin(phi + g))
    h = _circles(f, p["l6"], c, p["l5"], sides[1])
    k = (p["l6"] + p["l66"]) / p["l6"]
    return tuple(fi + k * (hi - fi) for fi, hi in zip(f, h))


def angles(p, phi, sides=SIDES):
    """(φ3, φ4, φ6) (rad) of the model, to check its branches against the file's start."""
    b = (p["l2"] * np.cos(phi), p["l2"] * np.sin(phi))
    e = (p["l8"], p["l7"])
    d = _circles(b, p["l3"], e, p["l44"], sides[0])
    f = tuple(di + p["l4"] * (ei - di) / p["l44"] for di, ei in zip(d, e))
    g = np.radians(p["gamma"])
    c = (-p["l22"] * np.cos(phi + g), -p["l22"] * np.sin(phi + g))
    h = _circles(f, p["l6"], c, p["l5"], sides[1])
    return (np.arctan2(d[1] - b[1], d[0] - b[0]), np.arctan2(e[1] - d[1], e[0] - d[0]),
            np.arctan2(h[1] - f[1], h[0] - f[0]))


def _dx(p, phi, w):
    """d/dφ of w·Z by the complex step (exact to rounding)."""
    hs = 1e-30
    zx, zy = z(p, phi + 1j * hs)
    return (w[0] * zx.imag + w[1] * zy.imag) / hs


def travel(p, axis=(1.0, 0.0), n=720, steps=8):
    """(designs,) max − min over the turn of Z's projection on the unit vector `axis`, each extreme
    refined by Newton on the derivative (module doc). `p`: dict of (designs,) arrays."""
    p = {k: np.asarray(v, float)[:, None] for k, v in p.items()}
    phis = 2.0 * np.pi * np.arange(n) / n
    zx, zy = z(p, phis[None, :])
    proj = axis[0] * zx + axis[1] * zy
    out = []
    for sign in (1.0, -1.0):
        phi = phis[np.argmax(sign * proj, axis=1)][:, None]
        for _ in range(steps):
            d1 = _dx(p, phi, axis)
            dd = 1e-5
            d2 = (_dx(p, phi + dd, axis) - _dx(p, phi - dd, axis)) / (2 * dd)
            phi = phi - np.clip(d1 / d2, -np.pi / n, np.pi / n)
        zx, zy = z(p, phi)
        out.append((axis[0] * zx + axis[1] * zy)[:, 0])
    return out[0] - out[1]
