"""``python -m nearopt …``: the ``nearopt`` command (:mod:`nearopt.cli`)."""

from .cli import main

if __name__ == "__main__":
    raise SystemExit(main())
