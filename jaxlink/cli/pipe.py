"""A closed standard output never stops a command: `jaxlink kinematics four-bar --csv x.csv | true`
still writes x.csv.

When the reader of the output goes away (`| true`, `| head -1`), a write to standard output raises
`BrokenPipeError`. Raised through the command, it ended the command before the files it was asked
for were written, with exit status 0. Here the first broken write points standard output at the
null device instead and the command goes on: what it prints is dropped (nobody reads it), the files
are written, and the exit status is the command's own (2 naming the file that could not be
written, as always).
"""

from __future__ import annotations

import contextlib
import os
import sys
from typing import Iterator


class QuietStream:
    """A text stream (standard output) whose writes and flushes never raise `BrokenPipeError`:
    the first one that would sends the stream to the null device (`os.devnull`, through its file
    descriptor, so that the buffered rest and the flush at exit go there too). Everything else is
    the wrapped stream's."""

    def __init__(self, stream):
        self._stream = stream
        self.closed_pipe = False

    def _quiet(self) -> None:
        self.closed_pipe = True
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            try:
                os.dup2(devnull, self._stream.fileno())
            finally:
                os.close(devnull)
        except (OSError, ValueError, AttributeError):  # a stream without a file descriptor (a test's)
            pass

    def write(self, text: str) -> int:
        if self.closed_pipe:
            return len(text)
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._quiet()
            return len(text)

    def flush(self) -> None:
        if self.closed_pipe:
            with contextlib.suppress(OSError, ValueError):
                self._stream.flush()  # to the null device: empties the buffer
            return
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._quiet()
            with contextlib.suppress(OSError, ValueError):
                self._stream.flush()

    def writelines(self, lines) -> None:
        for line in lines:
            self.write(line)

    def __getattr__(self, name):
        return getattr(self._stream, name)


@contextlib.contextmanager
def quiet_closed_pipes() -> Iterator[tuple[QuietStream, QuietStream]]:
    """`sys.stdout` and `sys.stderr` as `QuietStream`s for the duration (`2>&1 | head -1` closes
    both); the streams that were there are put back."""
    before = sys.stdout, sys.stderr
    quiet = QuietStream(before[0]), QuietStream(before[1])
    sys.stdout, sys.stderr = quiet  # type: ignore[assignment]
    try:
        yield quiet
    finally:
        for stream in quiet:
            stream.flush()
        if sys.stdout is quiet[0]:
            sys.stdout = before[0]
        if sys.stderr is quiet[1]:
            sys.stderr = before[1]
