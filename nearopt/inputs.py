"""Reading the files a user gives: TOML files (scenes, tasks), with one error naming the file."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from .errors import ConfigurationError

__all__ = ["read_toml"]


def read_toml(
    path: object, error: type[ConfigurationError], what: str
) -> tuple[Path, dict[str, Any]]:
    """The absolute path of a TOML file and its contents (a leading byte-order mark allowed).

    Raises
    ------
    ConfigurationError
        Of type ``error``: not a path, a missing or unreadable file, or not TOML; the message
        names the ``what`` file (e.g. "scene") and the path.
    """
    if not isinstance(path, str | Path) or not str(path):
        raise error(f"a {what} file is a path, got {path!r}")
    path = Path(path).expanduser().resolve()
    try:
        return path, tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except OSError as exc:
        raise error(f"cannot read the {what} file {path}: {exc.strerror or exc}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise error(f"the {what} file {path} is not valid TOML: {exc}") from None
