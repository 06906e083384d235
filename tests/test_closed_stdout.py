"""A closed standard output never loses a file (issue 46 item 3): `jaxlink kinematics four-bar
--csv x.csv | true` writes x.csv (on 329192a it exited 0 without it, 8 runs of 8: the first print
raised `BrokenPipeError`, whose quiet exit came before the files).

Real processes with a real pipe. `| true` is made deterministic: the pipe's reading end is closed
before the command starts, so its first print meets a closed pipe. `| head -1`: the test reads one
line and closes the pipe, with more output to come than the pipe holds. The files are checked
complete: every row of the CSV (the count asked for), the JSON parsed, the PNG ending in its IEND
chunk, the DXF in its EOF."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys

COUNT = 12
# the kinematics commands' count: more rows than a pipe holds (`| head -1`), and one program for
# both (the second loads it from the run's compile cache)
ROWS = 3000


def _run_closed(args: list[str], *, head: bool = False) -> subprocess.CompletedProcess:
    """`jaxlink ARGS | true` (the reader gone before the command starts) or `| head -1`."""
    read, write = os.pipe()
    if not head:
        os.close(read)
    try:
        proc = subprocess.Popen([sys.executable, "-m", "jaxlink.cli", *args], stdout=write,
                                stderr=subprocess.PIPE, text=True)
    finally:
        os.close(write)
    if head:
        with os.fdopen(read, "rb") as fh:
            first = fh.readline()
        assert first, "no first line"
    _, err = proc.communicate(timeout=300)
    return subprocess.CompletedProcess(args, proc.returncode, "", err)


def _rows(path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(line for line in fh if not line.startswith("#")))


def test_kinematics_writes_its_files_into_a_closed_pipe(tmp_path):
    out = {k: tmp_path / f"k.{k}" for k in ("csv", "json", "png")}
    done = _run_closed(["kinematics", "four-bar", "--count", str(ROWS), "--csv", str(out["csv"]),
                        "--json", str(out["json"]), "--plot", str(out["png"])])
    assert done.returncode == 0, done.stderr
    assert len(_rows(out["csv"])) == ROWS
    json.loads(out["json"].read_text())
    assert out["png"].read_bytes()[-8:-4] == b"IEND"


def test_reactions_writes_its_csv_into_a_closed_pipe(tmp_path):
    path = tmp_path / "r.csv"
    done = _run_closed(["reactions", "slider-crank-mass", "--count", str(COUNT), "--csv", str(path)])
    assert done.returncode == 0, done.stderr
    assert len(_rows(path)) == COUNT


def test_the_export_after_a_table_cut_by_head(tmp_path):
    """`--csv -` sends 3000 rows (more than a pipe holds) to `head -1`; the export written after
    the table is written whole."""
    path = tmp_path / "k.dxf"
    done = _run_closed(["kinematics", "four-bar", "--count", str(ROWS), "--csv", "-", "--export", str(path)],
                       head=True)
    assert done.returncode == 0, done.stderr
    assert path.read_text().rstrip().endswith("EOF")


def test_a_closed_stdout_in_process_is_quiet(capsys, tmp_path):
    """`pipe.QuietStream`: a write that meets a closed pipe is dropped, the next ones too, and the
    command goes on."""
    from jaxlink.cli.pipe import QuietStream

    class Closed:
        def write(self, text):
            raise BrokenPipeError(32, "Broken pipe")

        def flush(self):
            raise BrokenPipeError(32, "Broken pipe")

    quiet = QuietStream(Closed())
    assert quiet.write("lost\n") == 5 and quiet.closed_pipe
    quiet.write("also lost\n")
    quiet.flush()
