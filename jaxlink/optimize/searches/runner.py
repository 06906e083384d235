"""`run`: one design search driven chunk by chunk, with checkpoints (`checkpoint.py`) and an
optional progress bar; returns a `SearchResult`."""

from __future__ import annotations

import os
import time

import jax
import numpy as np

from ...errors import MechanismError
from .. import checkpoint as _checkpoint
from ..evaluator import Evaluator
from ..problem import Problem
from . import searcher
from .result import SearchResult, summarized


def run(problem_or_evaluator: Problem | Evaluator, method: str, *, budget: int, seed: int = 0,
        out: str | os.PathLike | None = None, resume: bool = False, progress: bool = False,
        chunk: int | None = None, stop_after_chunks: int | None = None, checkpoint_s: float = 2.0,
        **knobs) -> SearchResult:
    """Search the design space of a problem for the lowest objective.

    **Arguments:**

    - `problem_or_evaluator`: a `Problem` (an `Evaluator` is built for it) or an `Evaluator`
      (its compiled functions are reused by later searches on it).
    - `method`: "uniform", "montecarlo" or "gradient" (`jaxlink.optimize.searches.searcher`).
    - `budget`: mechanism evaluations allowed; `seed`: the random seed (same seed, same result).
    - `out`: the JSON document's path; the state is checkpointed beside it after every chunk
      (`OUT.state.npz`, `OUT.log.jsonl`, `OUT` rewritten with the best so far) and `OUT` ends
      with `SearchResult.to_json()`. `resume`: continue the interrupted search of `out`; it ends
      with exactly the result of an uninterrupted one.
    - `progress`: a tqdm bar on stderr. `chunk`: designs per batch when a `Problem` is given
      (default `[optimize] chunk`, else from the device and the problem: `Evaluator`).
    - `checkpoint_s`: seconds between checkpoints (the first chunk, then at most every
      `checkpoint_s`, and at the end; a kill loses at most that much work, and the resumed search
      still ends exactly as an uninterrupted one). 0: after every chunk.
    - `stop_after_chunks` (testing): stop after that many chunks of this call, as if killed.
    - `knobs`: the method's options (`uniform`, `starts`, `presample`, `iterations`, …).
    """
    if isinstance(problem_or_evaluator, Evaluator):
        ev = problem_or_evaluator
    else:
        ev = Evaluator(problem_or_evaluator, chunk=chunk or problem_or_evaluator.option("chunk", None))
    search = searcher(ev, method, budget=budget, seed=seed, **knobs)
    extra = {"uniform": knobs.get("uniform", "grid")} if method == "uniform" else {}
    fp = _checkpoint.fingerprint(ev.problem, method, seed, budget, repr(sorted(knobs.items())))
    files = _checkpoint.paths(out) if out else None
    writer = jax.process_index() == 0  # several processes (distributed.py): process 0 writes
    st = search.init()
    saved = None
    if resume:
        if not files:
            raise MechanismError("--resume needs --out (the search's output file)")
        saved = _checkpoint.load_state(files[1], st, fp)
    if saved is not None:
        st = saved
    elif files and writer:
        files[2].unlink(missing_ok=True)
        files[1].unlink(missing_ok=True)

    def result(complete: bool) -> SearchResult:
        return summarized(ev, method, st.progress, seed=seed, budget=budget, complete=complete, extra=extra)

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=budget, initial=int(st.progress.evaluations), unit="eval", desc=method, dynamic_ncols=True)
    chunks = 0
    pending: list[dict] = []  # log records of the chunks since the last checkpoint
    saved_at = -float("inf")

    def checkpoint():
        nonlocal saved_at
        if not writer:
            pending.clear()
            return
        _checkpoint.save_state(files[1], st, fp)
        for record in pending:
            _checkpoint.append_log(files[2], record)
        pending.clear()
        _checkpoint.write_json_atomic(files[0], result(False).to_json())
        saved_at = time.perf_counter()

    try:
        while not search.done(st):
            if stop_after_chunks is not None and chunks >= stop_after_chunks:
                break
            t0 = time.perf_counter()
            before = int(st.progress.evaluations)
            st = search.step(st)
            p = st.progress._replace(wall_s=np.float64(st.progress.wall_s + time.perf_counter() - t0))
            st = st._replace(progress=p)
            chunks += 1
            if bar is not None:
                bar.update(int(p.evaluations) - before)
                if p.found:
                    bar.set_postfix(best=f"{float(p.best_value):.6g}")
            if files:
                pending.append({
                    "chunk": int(p.chunk), "evaluations": int(p.evaluations), "designs": int(p.designs),
                    "infeasible": int(p.infeasible), "best_value": float(p.best_value) if p.found else None,
                    "best_parameters": (dict(zip(ev.problem.names, map(float, ev.problem.to_file_units(p.best_u))))
                                        if p.found else None),
                    "wall_s": float(p.wall_s),
                })
                if time.perf_counter() - saved_at >= checkpoint_s:
                    checkpoint()
        if files and pending:
            checkpoint()  # the last chunks (also of a search stopped by stop_after_chunks)
    finally:
        if bar is not None:
            bar.close()
    res = result(search.done(st))
    if files and writer:
        _checkpoint.write_json_atomic(files[0], res.to_json())
    return res
