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
closes iff S ≥ 0, and it stays on its branch between two inputs iff S > 0 between them.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .topology import CRANK, Topology


def _margin(l1, l2, d2):
    return ((l1 + l2) ** 2 - d2) * (d2 - (l1 - l2) ** 2) / (4.0 * l1 * l1 * l2 * l2)


def _norm(v):
    return jnp.sqrt(jnp.sum(v * v, axis=-1) + 1e-30)


def trace(parents, active, pose, thetas):
    """Positions (T, J, 2) and margins (T, D) (1 where inactive) of one
    candidate over the input offsets `thetas` (T,). A dyad that does not close puts its joint on
    the line P₁P₂ (h = 0): finite, its margin negative. Pure; `vmap` over candidates."""
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
        h = l1 * l2 * jnp.sqrt(jnp.where(ok, s, 1.0)) * ok / d
        a = (l1 * l1 - l2 * l2 + d2) / (2.0 * d)
        perp = jnp.stack([-w[:, 1], w[:, 0]], axis=-1)
        jpos = a1 + (a / d)[:, None] * w + (sigma * h / d)[:, None] * perp
        pos = pos.at[:, j].set(jnp.where(active[k], jpos, pos[:, j]))
        margins.append(jnp.where(active[k], s, 1.0))
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
    for k, (p1, p2) in enumerate(topo.dyads):
        j = CRANK + 1 + k
        w0, v0 = pose[p2] - pose[p1], pose[j] - pose[p1]
        l1, l2 = np.hypot(*v0), np.hypot(*(pose[j] - pose[p2]))
        sigma = 1.0 if w0[0] * v0[1] - w0[1] * v0[0] >= 0 else -1.0
        w = pos[:, p2] - pos[:, p1]
        d2 = np.sum(w * w, axis=-1)
        d = np.sqrt(d2)
        s = _margin(l1, l2, d2)
        margins[:, k] = s
        h = l1 * l2 * np.sqrt(np.maximum(s, 0.0)) / d
        a = (l1 * l1 - l2 * l2 + d2) / (2.0 * d)
        perp = np.stack([-w[:, 1], w[:, 0]], axis=-1)
        pos[:, j] = pos[:, p1] + (a / d)[:, None] * w + (sigma * h / d)[:, None] * perp
    return pos, margins


def lengths(topo: Topology, pose: np.ndarray) -> dict[str, float]:
    """The dimensions a pose fixes: the crank and each dyad's two links."""
    pose = np.asarray(pose, float)
    out = {"crank": float(np.hypot(*(pose[CRANK] - pose[0])))}
    for k, (p1, p2) in enumerate(topo.dyads):
        j = CRANK + 1 + k
        out[f"l{j}_{p1}"] = float(np.hypot(*(pose[j] - pose[p1])))
        out[f"l{j}_{p2}"] = float(np.hypot(*(pose[j] - pose[p2])))
    return out


#: jitted batched trace: (parents (B, D, 2), active (B, D), poses (B, J, 2), thetas (B, T))
trace_batch = jax.jit(jax.vmap(trace))
