"""`jaxlink synthesize`'s progress line on standard error (`cli.synthesize._Status`): rewritten in
place on a terminal, the search's log lines printed above it; a line per step elsewhere; the
options that choose it (`--progress`, `--quiet`). No search: the line's records are made here."""

import io
import math

from jaxlink.synthesis.progress import Progress


def _p(stage="scored", **kw):
    base = dict(stage=stage, round=1, polish=False, scored=3, topologies=16, distance=0.0123, topology="watt-1",
                joints=7, transmission_deg=38.4, elapsed_s=4.2, left_s=25.8)
    base.update(kw)
    return Progress(**base)


def test_the_status_line_on_a_terminal_and_elsewhere():
    from jaxlink.cli.synthesize import _Status

    out = io.StringIO()
    st = _Status(out, True, "synthesis/synthesized.toml")
    st.show(_p("compiling", round=0, scored=0, distance=math.nan, topology="", joints=0, transmission_deg=math.nan,
               elapsed_s=0.4, left_s=29.6))
    st.show(_p())
    st.log("round 1: 32 candidates")
    st.close()
    text = out.getvalue()
    assert text == ("\rcompiling the programs | no design yet | 0 s, 30 s left\x1b[K"
                    "\rround 1: 3/16 topologies scored | best 0.0123 (watt-1, 7 joints, mu 38 deg) in "
                    "synthesis/synthesized.toml | 4 s, 26 s left\x1b[K"
                    "\rround 1: 32 candidates\x1b[K\nround 1: 3/16 topologies scored | best 0.0123 (watt-1, 7 joints, "
                    "mu 38 deg) in synthesis/synthesized.toml | 4 s, 26 s left\n")
    out = io.StringIO()
    st = _Status(out, False, None)
    st.show(_p(left_s=None, polish=True))
    st.log("round 2 (polish): 40 candidates")
    st.close()
    assert out.getvalue() == ("round 1 (polish): 3/16 topologies scored | best 0.0123 (watt-1, 7 joints, mu 38 deg) "
                              "| 4 s\nround 2 (polish): 40 candidates\n")


def test_the_progress_options():
    from jaxlink.cli import build_parser

    parse = build_parser().parse_args
    assert (parse(["synthesize", "x.csv"]).progress, parse(["synthesize", "x.csv"]).quiet) == ("auto", False)
    assert parse(["synthesize", "x.csv", "--progress", "on", "--quiet"]).quiet
    assert parse(["synthesize", "x.csv", "--progress", "off"]).progress == "off"
