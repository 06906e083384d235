"""Formatting a synthesis (`jaxlink.synthesis.api.Synthesis`): the table, the JSON of the ranked
designs, the plot of the target over the traced curve with the linkage, the mechanism file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def _short(violates) -> str:
    """The bounds a design breaks, in a word each (`bounds.violations`' first words): "mu", "link", "pivot"."""
    words = {"transmission": "mu", "link": "link", "frame": "pivot"}
    return ",".join(words.get(v.split()[0], v.split()[0]) for v in violates)


def table(res) -> str:
    """The bounds in force (`bounds.describe`), then one line per design: topology, joints, links,
    distance (phase-free, the ranking), LInK's metric (`link2000`; "-" for a timed target), size, least
    transmission angle, whether it meets the bounds (`bounds`: "yes", or the ones it breaks), crank
    interval, time found, on the Pareto front; then the simplest design within 10 % of the best."""
    t = res.target
    kind = (f"timed over {abs(np.degrees(t.inputs[-1] - t.inputs[0])):.6g}° (distance: the ordered one)" if t.timed
            else "closed" if t.closed else "open")
    unit = f" {t.unit}" if t.unit else ""
    from ..synthesis.bounds import describe

    lines = [f"target      {t.source}: {len(t.points)} points, {kind}" + (f", in {t.unit}" if t.unit else ""),
             f"extent      {res.extent:.6g}{unit} (the largest distance between two target points: the unit of "
             "`size`, the longest link or the frame pivot furthest from the target's centre)",
             f"bounds      {describe(res.bounds)}"]
    if not res.meets:
        b = res.best
        lines.append(f"NO DESIGN   meets the bounds: the best found, {b.topology}, breaks them "
                     f"({'; '.join(b.violates)}); give more --rounds or --samples, or looser bounds")
    lines.append(f"{'rank':>4}  {'topology':<26}{'joints':>7}{'links':>6}{'distance':>11}{'link2000':>10}{'size':>7}"
                 f"{'mu_deg':>8}{'bounds':>11}{'start_deg':>11}{'stop_deg':>11}{'found_s':>9}  pareto")
    for i, d in enumerate(res.designs, 1):
        link = "-" if np.isnan(d.link_chamfer_2000) else f"{d.link_chamfer_2000:.5f}"
        lines.append(f"{i:>4}  {d.topology:<26}{d.joints:>7}{d.links:>6}{d.distance:>11.5f}{link:>10}{d.size:>7.2f}"
                     f"{d.transmission_deg:>8.1f}{'yes' if d.meets else _short(d.violates):>11}"
                     f"{d.start_deg:>11.3f}{d.stop_deg:>11.3f}{d.found_s:>9.1f}  {'*' if d.pareto else ''}")
    if res.simplest is not None:
        s = res.designs[res.simplest]
        top = min(d.distance for d in res.designs if d.meets or not res.meets)
        lines.append(f"simplest    rank {res.simplest + 1}, {s.topology} ({s.joints} joints): distance "
                     f"{s.distance:.5f}, within 10 % of the best {top:.5f}")
    lines.append(f"wall time   {res.wall_s:.1f} s, {res.rounds} round{'s' if res.rounds != 1 else ''}")
    if res.stopped_by == "time_limit":
        lines.append(f"stopped     at the time limit ({res.time_limit:g} s): the designs depend on the machine's "
                     "speed; --rounds N without --time-limit for designs that do not")
    return "\n".join(lines)


def progress_line(p, best_file: str | None = None) -> str:
    """One line of a running synthesis (`jaxlink.synthesis.progress.Progress`): the stage and round,
    the topologies scored, the best design so far (its distance, topology, joints and least
    transmission angle, and `best_file`, where the best design so far is written, if given), the
    time spent and, with a limit, the time left."""
    if p.stage == "compiling":
        where = "compiling the programs"
    elif p.stage == "done":
        where = f"done after {p.round} round{'s' if p.round != 1 else ''}"
    else:
        where = f"round {p.round}{' (polish)' if p.polish else ''}: {p.scored}/{p.topologies} topologies scored"
        if p.stage == "polished":
            where = f"round {p.round}: float64 polish"
    best = "no design yet" if not p.topology else (
        f"best {p.distance:.4g} ({p.topology}, {p.joints} joints, mu {p.transmission_deg:.0f} deg)")
    if p.topology and best_file:
        best += f" in {best_file}"
    clock = f"{p.elapsed_s:.0f} s" + (f", {max(0.0, p.left_s):.0f} s left" if p.left_s is not None else "")
    return f"{where} | {best} | {clock}"


def to_json(res) -> dict:
    """The JSON of the ranked designs (docs/reference/cli.md, `jaxlink synthesize`)."""
    t = res.target
    return {
        "target": {"source": t.source, "points": len(t.points), "closed": t.closed, "unit": t.unit,
                   "timed": t.timed, "extent": res.extent},
        "max_size": res.max_size,
        "min_transmission_deg": res.min_transmission,
        "max_pivot": res.max_pivot,
        "bounds_met": res.meets,
        "simplest": None if res.simplest is None else {"rank": res.simplest + 1,
                                                       "topology": res.designs[res.simplest].topology},
        "wall_s": res.wall_s,
        "interrupted": res.interrupted,
        "rounds": res.rounds,
        "stopped_by": res.stopped_by,
        "time_limit_s": res.time_limit,
        "designs": [{
            "rank": i, "topology": d.topology, "joints": d.joints, "links": d.links,
            "distance": d.distance,
            "link_chamfer_2000": None if np.isnan(d.link_chamfer_2000) else d.link_chamfer_2000,
            "start_deg": d.start_deg, "stop_deg": d.stop_deg, "count": d.n_inputs,
            "scale": d.scale, "rotation_deg": d.rotation_deg, "translation": list(d.translation),
            "margin": d.margin, "size": d.size, "link_size": d.link_size, "pivot_size": d.pivot_size,
            "transmission_deg": d.transmission_deg, "meets": d.meets, "violates": list(d.violates),
            "lengths": d.lengths,
            "found_s": d.found_s, "pareto": d.pareto,
            "joint_positions": d.sketch.tables()["sketch"]["joints"],
            "links_joints": d.sketch.tables()["sketch"]["links"],
            "frame": d.sketch.tables()["sketch"]["frame"],
            "sliders": {j: v["along"] for j, v in d.sketch.tables()["sketch"].get("sliders", {}).items()
                        if "along" in v},
            "levers": {j: {"on": v["on"], "through": v["through"]}
                       for j, v in d.sketch.tables()["sketch"].get("sliders", {}).items() if "through" in v},
            "inputs_deg": None if d.inputs_deg is None else [float(x) for x in d.inputs_deg],
        } for i, d in enumerate(res.designs, 1)],
    }


def write_json(path, res) -> None:
    Path(path).write_text(json.dumps(to_json(res), indent=2) + "\n")


def plot(path, res) -> None:
    """The target over the best design's traced curve, the linkage drawn at the interval's start."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = res.best
    t = res.target.points
    sk = d.sketch.tables()["sketch"]
    fig, ax = plt.subplots(figsize=(6.4, 6.0))
    tt = np.concatenate([t, t[:1]]) if res.target.closed and not res.target.timed else t
    ax.plot(tt[:, 0], tt[:, 1], color="0.6", lw=4, alpha=0.6, label="target")
    c = np.concatenate([d.curve, d.curve[:1]]) if res.target.closed and not res.target.timed else d.curve
    ax.plot(c[:, 0], c[:, 1], color="C0", lw=1.5, label=f"traced ({d.topology})")
    if d.at_inputs is not None:  # a timed target: each point and where the design is at its input
        ax.plot(t[:, 0], t[:, 1], ls="", marker="o", ms=3, color="0.3", label="target at its inputs")
        ax.plot(d.at_inputs[:, 0], d.at_inputs[:, 1], ls="", marker="x", ms=4, color="C3",
                label="traced at the same inputs")
        for a, b in zip(t, d.at_inputs):
            ax.plot([a[0], b[0]], [a[1], b[1]], color="C3", lw=0.6)
    js = sk["joints"]
    for names in sk["links"].values():
        pts = np.array([js[n] for n in names] + ([js[names[0]]] if len(names) > 2 else []))
        ax.plot(pts[:, 0], pts[:, 1], color="C1", lw=1.2)
    size = float(np.max(np.ptp(np.concatenate([t, d.curve, np.array(list(js.values()))]), axis=0)))
    for n, v in sk.get("sliders", {}).items():  # a slider's frame guide, dashed, through its joint
        if "through" in v:  # a slotted lever's slot: from its pivot through the block's pin and on
            a, b = np.asarray(js[v["through"]], float), np.asarray(js[n], float)
            u = (b - a) / np.hypot(*(b - a))
            g = a + np.outer([0.0, np.hypot(*(b - a)) + 0.2 * size], u)
            ax.plot(g[:, 0], g[:, 1], color="C1", lw=0.8, ls="--")
            continue
        u = np.asarray(v["along"], float) / np.hypot(*v["along"])
        g = np.asarray(js[n]) + np.outer([-0.6 * size, 0.6 * size], u)
        ax.plot(g[:, 0], g[:, 1], color="k", lw=0.8, ls="--")
    for n, (x, y) in js.items():
        frame = n in sk["frame"]
        ax.plot([x], [y], marker="^" if frame else "o", color="k" if frame else "C1", ms=6 if frame else 4)
        ax.annotate(n, (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7)
    unit = d.sketch.length_unit
    ax.set_xlabel(f"x [{unit}]")
    ax.set_ylabel(f"y [{unit}]")
    ax.set_aspect("equal")
    ax.set_title(f"{d.topology}: distance {d.distance:.4f}, crank {d.start_deg:.1f}° to {d.stop_deg:.1f}°, "
                 f"size {d.size:.2f}, least transmission angle {d.transmission_deg:.1f}°"
                 + ("" if d.meets else f"\nbreaks the bounds: {'; '.join(d.violates)}"), fontsize=8)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def write_all(out_dir, res, *, plot_it: bool = True) -> list[Path]:
    """`synthesized.toml` (the best design), `designs/RANK-TOPOLOGY.toml` (each), `synthesis.json`,
    `synthesis.png` in `out_dir`."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = [out / "synthesized.toml"]
    files[0].write_text(res.best.sketch.toml())
    (out / "designs").mkdir(exist_ok=True)
    for i, d in enumerate(res.designs, 1):
        f = out / "designs" / f"{i}-{d.topology}.toml"
        f.write_text(d.sketch.toml())
        files.append(f)
    write_json(out / "synthesis.json", res)
    files.append(out / "synthesis.json")
    if plot_it:
        plot(out / "synthesis.png", res)
        files.append(out / "synthesis.png")
    return files
