"""``python -m bench.monitor``: the monitor alone (``bench monitor`` without the bench's CLI)."""

from __future__ import annotations

import argparse
import sys

from bench._errors import BenchError, error_line
from bench.monitor import add_arguments, main


def _main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="bench monitor", description="live terminal view of a running bench"
    )
    add_arguments(ap)
    args = ap.parse_args(argv)
    try:
        return main(args)
    except BenchError as e:
        print(error_line(e), file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(_main())
