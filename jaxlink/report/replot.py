"""`replot(DIR)`: redraw every plot of a study from its study.json and study.npz alone
(`jaxlink.report.study_files`) — no mechanism loaded, nothing evaluated or compiled."""

from __future__ import annotations

import pathlib

from .study_files import MechanismNames, read

__all__ = ["MechanismNames", "read", "replot"]


def replot(out_dir) -> list:
    """Redraw every plot of the study in `out_dir` from its study.json and study.npz (see the
    module doc); returns the paths drawn."""
    from . import sampling, screening, tolerance

    data, rep, names = read(out_dir)
    d = pathlib.Path(out_dir)
    method = data["method"]
    if method == "tolerance":
        files = tolerance.draw_plots(d, names, rep)
    elif method == "sensitivity":
        files = sampling.draw_sensitivity_plots(d, names, rep)
    elif method in ("morris", "regression", "dgsm"):
        path = d / f"{method}.png"
        files = [path] if screening.plot_indices(path, names, rep) else []
    else:
        files = sampling.draw_sample_plots(d, names, rep)
    return [str(f) for f in files]
