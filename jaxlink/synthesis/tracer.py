r"""Tracing a dyadic linkage (`topology`) from one pose: batched in JAX for the search, exactly
in NumPy float64 for the reported answers.

A candidate is its **pose**: every joint's position at input offset θ = 0, shape (4 + D, 2) for D
dyads (the frame joints F0–F2, the crank joint, the dyads' joints).
The pose fixes the lengths (the crank r = |C − F0|, each dyad's l₁ = |J − P₁|, l₂ = |J − P₂|) and
the branches (σ = sign((P₂ − P₁) × (J − P₁))). At input offset θ the crank joint is
F0 + r (cos(α + θ), sin(α + θ)), α its angle in the pose, and each dyad's joint is

.. math::  J = P_1 + \frac{a}{d} w + \sigma \frac{h}{d} w^\perp,\quad w = P_2 - P_1,\ d = |w|,\
           a = \frac{l_1^2 - l_2^2 + d^2}{2d},\ h = \frac{l_1 l_2}{d}\sqrt{S},

with the dyad's **reach margin** S = ((l₁ + l₂)² − d²)(d² − (l₁ − l₂)²) / (4 l₁² l₂²), the sine²
of the angle between its two links (the project's RRR margin, `jaxlink.solvers.dyads`): the dyad
closes iff S ≥ 0, and it stays on its branch between two inputs iff S > 0 between them. A dyad
that is a point of a rigid body (`topology.rigid`: its parents on one body, d constant) has no
such limit: it is carried with the body, J = P₁ + α w + β w⊥ with α = (w⁰·v⁰)/|w⁰|²,
β = (w⁰ × v⁰)/|w⁰|² from the pose (v⁰ = J⁰ − P₁⁰; smooth everywhere, a point on the line through
its parents included), and its margin is reported as 1 (its S is a constant of the design).

A **slider** dyad (`topology.slide`: RRP, the joint on the frame's line through the anchor
A = P₂ and its pose position J⁰, direction u = (J⁰ − A)/|J⁰ − A|) puts its joint at

.. math::  J = A + \left(u \cdot q + \sigma \sqrt{l_1^2 - e^2}\right) u,\quad q = P_1 - A,\
           e = u \times q,

with σ = sign(u · (J⁰ − P₁⁰)), l₁ = |J⁰ − P₁⁰|, and its margin S = 1 − e²/l₁² (the cosine² of the
angle between the link and the line; 0 where the link stands square to the line, the slider's
dead centre).

A **slotted lever** dyad (`topology.lever`: RPR, the lever turning about the frame joint P₁, the
block pinned at P₂ sliding in its slot, which lies on the line through the pivot) puts its joint,
a point of the lever, at

.. math::  J = P_1 + \frac{\lambda}{d} w + \frac{\mu}{d} w^\perp,\quad w = P_2 - P_1,\ d = |w|,

with λ = (w⁰·v⁰)/d⁰, μ = (w⁰ × v⁰)/d⁰ from the pose (v⁰ = J⁰ − P₁⁰): J keeps its place on the lever,
whose direction is that of w. Its margin S = d²/d⁰² is 0 only where the pin passes over the pivot
(the lever's angle undefined there); it has no toggle.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .topology import CRANK, LEVER, RIGID, SLIDER, Topology, rigid


def _margin(l1, l2, d2):
    return ((l1 + l2) ** 2 - d2) * (d2 - (l1 - l2) ** 2) / (4.0 * l1 * l1 * l2 * l2)


def _norm(v):
    return jnp.sqrt(jnp.sum(v * v, axis=-1) + 1e-30)


def _slid(a1, anchor, jp, l1, sigma):
    """A slider dyad's joint (…, 2) and margin (…) with its link's end at `a1` (…, 2), the guide
    through `anchor` and `jp` (its pose position), the link `l1`, the branch `sigma` (module doc). Where
    it does not close (S < 0) the joint is at the foot of the perpendicular from `a1`."""
    g = jp - anchor
    u = g / _norm(g)
    q = a1 - anchor
    along = q[..., 0] * u[0] + q[..., 1] * u[1]
    e = q[..., 0] * u[1] - q[..., 1] * u[0]
    s = 1.0 - (e * e) / (l1 * l1)
    ok = s > 0
    t = along + sigma * l1 * jnp.sqrt(jnp.where(ok, s, 1.0)) * ok
    return anchor + t[..., None] * u, s


def trace(parents, active, pose, thetas, sliders: bool = False):
    """Positions (T, J, 2) and margins (T, D) (1 where inactive) of one
    candidate over the input offsets `thetas` (T,). A dyad that does not close puts its joint on
    the line P₁P₂ (h = 0): finite, its margin negative. `sliders` (static): the parents may hold
    slider and slotted-lever dyads (`topology.as_arrays`: the second parent + `SLIDER`, + `LEVER`),
    each traced by every rule and its own kept; without it every dyad is RRR. Pure; `vmap` over
    candidates."""
    f0 = pose[0]
    c0 = pose[CRANK] - f0
    r = _norm(c0)
    alpha = jnp.arctan2(c0[1], c0[0])
    ang = alpha + thetas
    crank = f0 + r * jnp.stack([jnp.cos(ang), jnp.sin(ang)], axis=-1)
    pos = jnp.broadcast_to(pose, (thetas.shape[0],) + pose.shape)
    pos = pos.at[:, CRANK].set(crank)
    margins = []
    for k in range(parents.shape[0]):
        j = CRANK + 1 + k
        p1, p2 = parents[k, 0], parents[k, 1]
        if sliders:
            lever = p2 >= LEVER
            p2 = jnp.where(lever, p2 - LEVER, p2)
        fixed = p2 >= RIGID
        p2 = jnp.where(fixed, p2 - RIGID, p2)
        if sliders:
            slider = p2 >= SLIDER
            p2 = jnp.where(slider, p2 - SLIDER, p2)
        w0 = pose[p2] - pose[p1]
        v0 = pose[j] - pose[p1]
        l1 = _norm(v0)
        l2 = _norm(pose[j] - pose[p2])
        sigma = jnp.where(w0[0] * v0[1] - w0[1] * v0[0] >= 0, 1.0, -1.0)
        a1, a2 = pos[:, p1], pos[:, p2]
        w = a2 - a1
        d2 = jnp.sum(w * w, axis=-1) + 1e-30
        d = jnp.sqrt(d2)
        s = _margin(l1, l2, d2)
        ok = s > 0
        h = l1 * l2 * jnp.sqrt(jnp.where(ok, s, 1.0)) * ok / d  # a rigid point's S < 0 only by rounding: h = 0
        a = (l1 * l1 - l2 * l2 + d2) / (2.0 * d)
        perp = jnp.stack([-w[:, 1], w[:, 0]], axis=-1)
        jpos = a1 + (a / d)[:, None] * w + (sigma * h / d)[:, None] * perp
        ww = jnp.sum(w0 * w0) + 1e-30
        alpha = (w0[0] * v0[0] + w0[1] * v0[1]) / ww
        beta = (w0[0] * v0[1] - w0[1] * v0[0]) / ww
        jpos = jnp.where(fixed, a1 + alpha * w + beta * perp, jpos)
        if sliders:
            g = pose[j] - pose[p2]
            g_sigma = jnp.where(g @ (pose[j] - pose[p1]) >= 0, 1.0, -1.0)  # u · (J⁰ − P₁⁰), |g| > 0
            spos, ss = _slid(a1, pose[p2], pose[j], l1, g_sigma)
            jpos = jnp.where(slider, spos, jpos)
            s = jnp.where(slider, ss, s)
            d0 = jnp.sqrt(ww)  # a slotted lever: J's place on the lever, in units of length
            lpos = a1 + ((alpha * d0) / d)[:, None] * w + ((beta * d0) / d)[:, None] * perp
            jpos = jnp.where(lever, lpos, jpos)
            s = jnp.where(lever, d2 / ww, s)
        pos = pos.at[:, j].set(jnp.where(active[k], jpos, pos[:, j]))
        margins.append(jnp.where(active[k] & ~fixed, s, 1.0))
    return pos, jnp.stack(margins, axis=-1)


def trace_exact(topo: Topology, pose: np.ndarray, thetas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`trace` in NumPy float64 for one topology: positions (T, n, 2), margins (T, dyads)."""
    pose = np.asarray(pose, float)
    thetas = np.asarray(thetas, float)
    n = CRANK + 1 + len(topo.dyads)
    pos = np.repeat(pose[None, :n], thetas.shape[0], axis=0).copy()
    c0 = pose[CRANK] - pose[0]
    r = np.hypot(c0[0], c0[1])
    ang = np.arctan2(c0[1], c0[0]) + thetas
    pos[:, CRANK] = pose[0] + r * np.stack([np.cos(ang), np.sin(ang)], axis=-1)
    margins = np.empty((thetas.shape[0], len(topo.dyads)))
    fixed = rigid(topo)
    for k, (p1, p2) in enumerate(topo.dyads):
        j = CRANK + 1 + k
        if k in topo.levers:  # J's place on the lever turning about p1 through p2's pin (module doc)
            w0, v0 = pose[p2] - pose[p1], pose[j] - pose[p1]
            ww = w0[0] * w0[0] + w0[1] * w0[1]
            d0 = np.sqrt(ww)
            lam = (w0[0] * v0[0] + w0[1] * v0[1]) / d0
            mu = (w0[0] * v0[1] - w0[1] * v0[0]) / d0
            w = pos[:, p2] - pos[:, p1]
            d2 = np.sum(w * w, axis=-1)
            d = np.sqrt(d2)
            perp = np.stack([-w[:, 1], w[:, 0]], axis=-1)
            margins[:, k] = d2 / ww
            di = np.where(d > 0, 1.0 / np.where(d > 0, d, 1.0), 0.0)  # the pin on the pivot: J there, margin 0
            pos[:, j] = pos[:, p1] + (lam * di)[:, None] * w + (mu * di)[:, None] * perp
            continue
        if k in topo.sliders:
            g = pose[j] - pose[p2]
            u = g / np.hypot(*g)
            l1 = np.hypot(*(pose[j] - pose[p1]))
            sigma = 1.0 if g @ (pose[j] - pose[p1]) >= 0 else -1.0
            q = pos[:, p1] - pose[p2]
            e = q[:, 0] * u[1] - q[:, 1] * u[0]
            s = 1.0 - (e * e) / (l1 * l1)
            margins[:, k] = s
            # elementwise, not `q @ u`: a matrix product's rounding may depend on how many rows there are
            t = q[:, 0] * u[0] + q[:, 1] * u[1] + sigma * l1 * np.sqrt(np.maximum(s, 0.0))
            pos[:, j] = pose[p2] + t[:, None] * u
            continue
        w0, v0 = pose[p2] - pose[p1], pose[j] - pose[p1]
        l1, l2 = np.hypot(*v0), np.hypot(*(pose[j] - pose[p2]))
        sigma = 1.0 if w0[0] * v0[1] - w0[1] * v0[0] >= 0 else -1.0
        w = pos[:, p2] - pos[:, p1]
        d2 = np.sum(w * w, axis=-1)
        d = np.sqrt(d2)
        perp = np.stack([-w[:, 1], w[:, 0]], axis=-1)
        if fixed[k]:  # carried with its body (module doc)
            ww = w0[0] * w0[0] + w0[1] * w0[1]
            alpha = (w0[0] * v0[0] + w0[1] * v0[1]) / ww
            beta = (w0[0] * v0[1] - w0[1] * v0[0]) / ww
            margins[:, k] = 1.0
            pos[:, j] = pos[:, p1] + alpha * w + beta * perp
            continue
        s = _margin(l1, l2, d2)
        margins[:, k] = s
        d = np.where(d > 0, d, 1.0)  # parents on one point (a lever's pin over its pivot): finite, S < 0
        h = l1 * l2 * np.sqrt(np.maximum(s, 0.0)) / d
        a = (l1 * l1 - l2 * l2 + d2) / (2.0 * d)
        pos[:, j] = pos[:, p1] + (a / d)[:, None] * w + (sigma * h / d)[:, None] * perp
    return pos, margins


def lengths(topo: Topology, pose: np.ndarray) -> dict[str, float]:
    """The dimensions a pose fixes: the crank and each dyad's two links (a slider dyad's one link, and
    `e{j}`: its guide's offset, the distance of the crank's pivot F0 from the line; a slotted lever's
    joint its distance from the lever's pivot)."""
    pose = np.asarray(pose, float)
    out = {"crank": float(np.hypot(*(pose[CRANK] - pose[0])))}
    for k, (p1, p2) in enumerate(topo.dyads):
        j = CRANK + 1 + k
        out[f"l{j}_{p1}"] = float(np.hypot(*(pose[j] - pose[p1])))
        if k in topo.levers:  # J's distance from the lever's pivot only: the block slides
            continue
        if k in topo.sliders:
            g = pose[j] - pose[p2]
            q = pose[0] - pose[p2]
            out[f"e{j}"] = float(abs(q[0] * g[1] - q[1] * g[0]) / np.hypot(*g))
        else:
            out[f"l{j}_{p2}"] = float(np.hypot(*(pose[j] - pose[p2])))
    return out

