"""A killed study, for the resume tests: a `progress` callback that raises after a given batch."""


class Stop(Exception):
    """Raised by `stop_after`'s callback: the study was "killed"."""


def stop_after(k):
    """A `progress` callback that interrupts the study after its k-th batch (a killed study)."""
    calls = [0]

    def progress(_n):
        calls[0] += 1
        if calls[0] == k:
            raise Stop
    return progress
