"""Reading a YAML file with errors that name the file and say what went wrong."""

from __future__ import annotations

from pathlib import Path


def read_yaml(path: str | Path, error: type[Exception], what: str):
    """Parse ``path`` as YAML; an empty file is ``None``.

    Raises ``error`` with "<path>: cannot read <what> (...)" or "<path>: not valid YAML (...)".
    """
    import yaml

    path = Path(path)
    try:
        return yaml.safe_load(path.read_text())
    except OSError as exc:
        raise error(f"{path}: cannot read {what} ({exc.strerror or exc})") from None
    except yaml.YAMLError as exc:
        raise error(f"{path}: not valid YAML ({exc})") from None
