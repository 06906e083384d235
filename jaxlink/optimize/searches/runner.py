"""`run`: one design search driven chunk by chunk, with checkpoints (`checkpoint.py`) and an
optional progress bar; returns a `SearchResult`."""

from __future__ import annotations

import dataclasses
import os
import pathlib
import time as _time

import jax
import numpy as np

from ...errors import MechanismError
from .. import checkpoint as _checkpoint
from ..evaluator import Evaluator
from ..problem import Problem
from ..timing import compile_clock
from . import searcher
from .result import SearchResult, summarized, trace_point, traced


def evaluator_for(problem: Problem, chunk: int | None = None) -> Evaluator:
    """The `Evaluator` of `problem` for `chunk` designs per batch (default `[optimize] chunk`, else
    from the devices and the problem), made once per Problem object, chunk and device count and
    kept on the Problem (a private attribute; it goes with the Problem): a second search on the
    same Problem reuses its compiled functions instead of compiling them again (a new Evaluator
    compiles its batch, report and certificate: 8.5 s of a 20000-design Monte Carlo search of
    `sewing-feed-opt` whose search takes 0.12 s, on 2 CPU cores). An Evaluator holds no result
    of a search (a search's counts are in its own state), so a reused one gives the same answers
    (`tests/test_optimize.py`). `dataclasses.replace` of a Problem makes a new one, with its own."""
    chunk = chunk or problem.option("chunk", None)
    key = (chunk, jax.device_count(), jax.process_count())
    made = problem.__dict__.get("_evaluators")
    if made is None:
        made = {}
        object.__setattr__(problem, "_evaluators", made)  # frozen dataclass: a cache, not a field
    if key not in made:
        made[key] = Evaluator(problem, chunk=chunk)
    return made[key]


def run(problem_or_evaluator: Problem | Evaluator, method: str, *, budget: int | None = None, seed: int = 0,
        out: str | os.PathLike | None = None, resume: bool = False, progress: bool = False,
        chunk: int | None = None, stop_after_chunks: int | None = None, checkpoint_s: float = 2.0,
        time: float | None = None, started: float | None = None,
        **knobs) -> SearchResult:
    """Search the design space of a problem for the lowest objective.

    **Arguments:**

    - `problem_or_evaluator`: a `Problem` (its `Evaluator`, `evaluator_for`: made at its first
      search, reused by the later ones) or an `Evaluator` (its compiled functions are reused by
      later searches on it).
    - `method`: "uniform", "montecarlo" or "gradient" (`jaxlink.optimize.searches.searcher`).
    - `budget`: mechanism evaluations allowed; None (default): the gradient search chooses its
      sizes from the problem, stops when no start improves and takes at most `AUTO_BUDGET`
      (400 000), the others take 10000 (`searches.searcher`). Budgets are counts: `seed`, the
      same seed, the same result, on any machine and under any load.
    - `time`: a cap, in seconds of this call's wall time (compilation and the final report
      included; None: `[optimize] time`, else none). A chunk starts only if one as long as the
      last one fits in the time left (the final report's programs compile beside the search), so
      the call ends within about a chunk's time of the cap; the gradient search also ends its
      presample after 30 % of it. With a cap, `extra` holds `"time_limit_s"`. A search stopped
      by it depends on the machine's speed. `started`: when the time limit's clock started (a
      `time.perf_counter()` time; default: this call), e.g. the command's start, so that loading
      the file and building the evaluator count too.
    - `extra["stopped_by"]` says what ended the search: "time_limit", "budget", "iterations" or
      "converged" (the gradient search: no start improves), "interrupted" (`stop_after_chunks`, or
      Ctrl-C). A `KeyboardInterrupt` (Ctrl-C) once a design was found ends the search at its last
      whole chunk as its end would: the result is the best so far (certified as always), and with
      `out` the checkpoint, `OUT` and `OUT.best.toml` are written, from which `resume` continues to
      the uninterrupted result; before any design was found it is raised (nothing to keep).
    - `out`: the JSON document's path; the state is checkpointed beside it (`checkpoint_s`)
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
        ev = evaluator_for(problem_or_evaluator, chunk)
    if time is None:
        time = ev.problem.option("time")  # checked by problem_from
    elif isinstance(time, bool) or not isinstance(time, (int, float)) or not 0 < time <= 1e7:
        raise MechanismError(f"time = {time!r}: must be a number of seconds, more than 0 and at most 1e7")
    if isinstance(checkpoint_s, bool) or not isinstance(checkpoint_s, (int, float)) or not 0 <= checkpoint_s < 1e9:
        raise MechanismError(f"checkpoint_s = {checkpoint_s!r}: must be a number of seconds, 0 or more")
    search = searcher(ev, method, budget=budget, seed=seed, time=time, **knobs)
    if budget is None and not getattr(search, "auto", False):
        budget = int(search.budget)  # type: ignore[attr-defined]  # the method's default
    extra = {"uniform": knobs.get("uniform", "grid")} if method == "uniform" else {}
    fp = _checkpoint.fingerprint(ev.problem, method, seed, budget, repr(sorted(knobs.items())) + f"|{time}")
    if budget is None:
        budget = int(search.budget)  # type: ignore[attr-defined]  # the gradient search's AUTO_BUDGET
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

    # best-so-far over time: (evaluations, search seconds without compilation, objective) at
    # every chunk that improved it (a resumed search reads the earlier ones from its log)
    trace: list[dict] = []
    if saved is not None and files and files[2].exists():
        trace = traced(files[2])

    # a time limit is a cap on this call's whole time, the final report included: the report's
    # programs compile in a thread beside the search, and a chunk starts only if one as long as the
    # last one (without its compilation) fits in the time left
    t_call = _time.perf_counter() if started is None else float(started)
    warm = _report_ahead(ev) if time is not None else None
    stepped = 0.0  # seconds of this call in `search.step`
    last = 0.0  # the last chunk's seconds without compilation (the next one's estimate)
    if time is not None:
        extra["time_limit_s"] = float(time)

    def result(complete: bool) -> SearchResult:
        return summarized(ev, method, st.progress, seed=seed, budget=budget, complete=complete, extra=extra,
                          trace=trace)

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=budget, initial=int(st.progress.evaluations), unit="eval", desc=method,
                   dynamic_ncols=True)
    chunks = 0
    pending: list[dict] = []  # log records of the chunks since the last checkpoint
    saved_at = -float("inf")

    def checkpoint():
        nonlocal saved_at
        if not writer:
            pending.clear()
            return
        _checkpoint.save_state(files[1], st, fp)
        while pending:  # one by one: a Ctrl-C between two leaves the rest for the next checkpoint
            _checkpoint.append_log(files[2], pending[0])
            pending.pop(0)
        _checkpoint.write_json_atomic(files[0], result(False).to_json())
        saved_at = _time.perf_counter()

    timed_out = interrupted = False
    try:
        try:
            while not search.done(st):
                if stop_after_chunks is not None and chunks >= stop_after_chunks:
                    break
                if time is not None:
                    spent = float(st.progress.wall_s) + (_time.perf_counter() - t_call - stepped)
                    if spent + last > float(time):
                        timed_out = True
                        break
                t0 = _time.perf_counter()
                before = int(st.progress.evaluations)
                best_before = float(st.progress.best_value)
                with compile_clock() as clock:
                    st = search.step(st)
                dt = _time.perf_counter() - t0
                stepped += dt
                last = max(0.0, dt - clock[0])
                p = st.progress._replace(wall_s=np.float64(st.progress.wall_s + dt),
                                         compile_s=np.float64(st.progress.compile_s + clock[0]))
                st = st._replace(progress=p)
                if p.found and float(p.best_value) < best_before:
                    trace.append(trace_point(p))
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
                        "wall_s": float(p.wall_s), "compile_s": float(p.compile_s),
                    })
                    if _time.perf_counter() - saved_at >= checkpoint_s:
                        checkpoint()
        except KeyboardInterrupt:  # Ctrl-C: the search ends at its last whole chunk (the one cut is dropped)
            if not bool(st.progress.found):
                raise  # nothing found yet: nothing to keep
            interrupted = True
        if files and pending:
            checkpoint()  # the last chunks (also of a search stopped by stop_after_chunks)
    finally:
        if bar is not None:
            bar.close()
    if timed_out:
        extra["stopped_by"] = "time_limit"
    elif interrupted or not search.done(st):
        extra["stopped_by"] = "interrupted"  # Ctrl-C, or stop_after_chunks
    else:
        reason = getattr(search, "stop_reason", None)
        extra["stopped_by"] = reason(st) if reason is not None else "budget"
    if warm is not None:
        warm.result()
    res = result(search.done(st) or timed_out)
    if files and writer:
        if res.parameters is not None and ev.mech.file and os.path.isfile(ev.mech.file):
            path = best_file_path(files[0])
            path.write_text(res.best_file_text(), encoding="utf-8")
            res = dataclasses.replace(res, best_file=str(path))
        _checkpoint.write_json_atomic(files[0], res.to_json())
    return res


def _report_ahead(ev: Evaluator):
    """The final report's programs (`Evaluator.report` of the file's design: its re-solve and its
    certificate) compiled in a thread while the search runs; the future's `result()` waits for them
    (a time-limited search's report then runs warm within its limit)."""
    from concurrent.futures import ThreadPoolExecutor

    pr = ev.problem
    u = np.clip(pr.to_unit(pr.file_design()), 0.0, 1.0)
    executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="jaxlink-report")
    try:
        return executor.submit(_quietly, ev.report, u, 0)
    finally:
        executor.shutdown(wait=False)


def _quietly(fn, *args):
    """`fn(*args)`, or None where it raises (a warm-up: the real call raises what it raises)."""
    try:
        return fn(*args)
    except Exception:  # noqa: BLE001
        return None


def best_file_path(out) -> pathlib.Path:
    """`OUT.best.toml` beside the search's JSON document `OUT.json`."""
    out = pathlib.Path(out)
    stem = out.with_suffix("") if out.suffix == ".json" else out
    return pathlib.Path(str(stem) + ".best.toml")
