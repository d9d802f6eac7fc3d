"""Model files: ``.npz`` archives of arrays plus JSON metadata, written and read without pickles.

Pure file I/O: this module knows the file format, not the agents (it imports no agent class).
A model file is a NumPy ``.npz`` archive holding the learned arrays and one string array,
``metadata``: JSON with a format marker and version, the agent's class (module and qualified
name), its hyper-parameters, spaces and training clock (see
:meth:`~delayed_rl.agents.base.TabularAgent.save`). It is read with ``allow_pickle=False``, so
loading a model file can never run code.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "read_model_file",
    "resolve_model_path",
    "space_from_json",
    "space_to_json",
    "write_model_file",
]

FORMAT = "delayed_rl.agent"
"""The ``format`` marker of every model file's metadata."""
FORMAT_VERSION = 1
"""The newest format version this library writes and reads."""


def write_model_file(path: str | Path, metadata: dict[str, Any], arrays: dict[str, Any]) -> Path:
    """Write ``arrays`` and ``metadata`` (made JSON, with the format marker) to ``path``.

    ``.npz`` is appended when ``path`` has no suffix; parent folders are created.

    Returns:
        The path written.
    """
    path = Path(path)
    if not path.suffix:
        path = path.with_suffix(".npz")
    header = {"format": FORMAT, "format_version": FORMAT_VERSION, **metadata}
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as file:
        np.savez_compressed(file, **arrays, metadata=np.array(json.dumps(header)))
    return path


def resolve_model_path(path: str | Path) -> Path:
    """``path``, or ``path`` + ``.npz`` when only that exists.

    Raises:
        FileNotFoundError: neither exists.
    """
    path = Path(path)
    if not path.exists() and path.with_name(path.name + ".npz").exists():
        path = path.with_name(path.name + ".npz")
    if not path.exists():
        raise FileNotFoundError(f"no model file at {path} (nor {path}.npz)")
    return path


def read_model_file(path: Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Read a model file: its metadata (format checked) and its other arrays.

    Raises:
        ValueError: the file is not a readable ``.npz`` archive, has no metadata, the metadata is
            not this format's, or its version is newer than :data:`FORMAT_VERSION`.
    """
    arrays = _read_arrays(path)
    raw = arrays.pop("metadata", None)
    where = str(path)
    if raw is None or raw.shape != () or raw.dtype.kind != "U":
        raise ValueError(
            f"{where} is not a delayed-rl model file: it has no metadata string (arrays: "
            f"{sorted(arrays)})"
        )
    try:
        metadata = json.loads(str(raw))
    except json.JSONDecodeError as error:
        raise ValueError(f"{where}: the metadata is not valid JSON: {error}") from None
    if not isinstance(metadata, dict) or metadata.get("format") != FORMAT:
        raise ValueError(
            f"{where} is not a delayed-rl model file (its metadata lacks format={FORMAT!r})"
        )
    version = metadata.get("format_version")
    if not isinstance(version, int) or version > FORMAT_VERSION:
        raise ValueError(
            f"{where} has model format version {version!r}; this delayed-rl reads versions up "
            f"to {FORMAT_VERSION} (upgrade delayed-rl)"
        )
    return metadata, arrays


def _read_arrays(path: Path) -> dict[str, np.ndarray]:
    try:
        data = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as error:
        raise _unreadable(path, error) from None
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise ValueError(
            f"{path} is not a delayed-rl model file: it holds a single .npy array, not an .npz "
            "archive"
        )
    try:
        with data:
            return {key: data[key] for key in data.files}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as error:
        raise _unreadable(path, error) from None


def _unreadable(path: Path, error: Exception) -> ValueError:
    return ValueError(
        f"{path} is not a readable delayed-rl model file (.npz archive read with "
        f"allow_pickle=False): {error}"
    )


def space_to_json(space: spaces.Discrete) -> dict[str, Any]:
    """A ``Discrete`` space as JSON."""
    return {"type": "Discrete", "n": int(space.n), "start": int(space.start)}


def space_from_json(data: Any, name: str, where: str) -> spaces.Discrete:
    """The ``Discrete`` space that :func:`space_to_json` described.

    Raises:
        ValueError: ``data`` is not such a description (the message names ``where`` and ``name``).
    """
    if (
        not isinstance(data, dict)
        or data.get("type") != "Discrete"
        or not isinstance(data.get("n"), int)
        or not isinstance(data.get("start"), int)
        or data["n"] < 1
    ):
        raise ValueError(f"{where}: malformed {name} in the metadata: {data!r}")
    return spaces.Discrete(data["n"], start=data["start"])
