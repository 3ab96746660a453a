"""Reading the package's YAML inputs (parameter files, training and scoring settings, scripts)
with errors of one line: the file, the line and what is wrong, never a parser traceback."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from .errors import HapticAnfisError

__all__ = ['YamlFileError', 'read_yaml', 'yaml_error']


class YamlFileError(HapticAnfisError, ValueError):
    """A YAML input is missing, unreadable or not valid YAML (the message names the file:line)."""


def yaml_error(path: str | Path, exc: Exception) -> YamlFileError:
    """The one-line error for a ``yaml.YAMLError`` met reading ``path``."""
    mark = getattr(exc, 'problem_mark', None) or getattr(exc, 'context_mark', None)
    line = f':{mark.line + 1}' if mark is not None else ''
    problem = getattr(exc, 'problem', None) or str(exc).splitlines()[0]
    return YamlFileError(f'{path}{line}: not valid YAML: {problem}')


def read_yaml(path: str | Path, what: str = 'file') -> Any:
    """The document of the YAML file ``path`` (None if empty).

    Raises:
        YamlFileError: missing / unreadable (``what`` names it: 'config file', ...) or malformed.
    """
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise YamlFileError(f'{path}: cannot read the {what}: {exc.strerror or exc}') from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise yaml_error(path, exc) from None
