"""``python -m assist.cli``: the ``ptw-assist`` program."""

from assist.cli import main

if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
