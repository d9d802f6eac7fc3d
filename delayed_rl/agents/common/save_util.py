"""Model files: ``.npz`` archives of arrays plus JSON metadata, written and read without pickles.

Pure file I/O: this module knows the file format, not the agents (it imports no agent class).
A model file is a NumPy ``.npz`` archive holding the learned arrays and one string array,
``metadata``: JSON with a format marker and version, the agent's class (module and qualified
name), its hyper-parameters, spaces and training clock (see
:meth:`~delayed_rl.agents.common.base.TabularAgent.save`).

Reading is defensive (:class:`ModelFile`): a model file can never run code (no pickles: an array
of Python objects is refused from its header) and never makes the reader allocate more than it
holds. The archive's directory and every member's ``.npy`` header (shape and dtype) are read
first, without decompressing any data; sizes are checked against the headers and against
:data:`MAX_MODEL_BYTES`, and the caller checks the headers against what the metadata declares
before any array is read. Every problem is one ``ValueError`` naming the file.
"""

from __future__ import annotations

import json
import math
import os
import struct
import zipfile
import zlib
from collections.abc import Collection
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from gymnasium import spaces
from numpy.lib import format as npy

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "MAX_METADATA_BYTES",
    "MAX_MODEL_BYTES",
    "ArrayHeader",
    "ModelFile",
    "check_model_path",
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
MAX_MODEL_BYTES = 2**30 + 2**24
"""The most bytes a model file's arrays may hold once decompressed (1 GiB + 16 MiB).

Room for the largest tables an agent may allocate (``delayed_rl.agents.common.q_table.MAX_TABLE_BYTES``,
1 GiB) plus the metadata and the small arrays. ``save`` refuses to write more and loading refuses
a file that declares more (a zip bomb) before decompressing it. Raise both limits together to
work with larger tables.
"""
MAX_METADATA_BYTES = 2**24
"""The most bytes the metadata string may take as a NumPy string (16 MiB, 4 bytes a character).

An agent's metadata takes a few KiB (Λ of 10⁵ delay estimates: 3 MiB); ``save`` refuses more,
and loading refuses more before parsing it (JSON objects take several times their text).
"""
_MAX_DIRECTORY_BYTES = 2**16
"""The largest archive directory read (a model file's lists a few members in under 2 KiB)."""
_MAX_NPY_HEADER = 10_000  # numpy's own limit (max_header_size)
_SUFFIXES = (".npz", ".zip")
_KINDS = "biufU"  # bool, integers, floats, text: what model files hold (never objects)
_HEADER_READERS = {(1, 0): npy.read_array_header_1_0, (2, 0): npy.read_array_header_2_0}
#: What reading a damaged archive may raise, besides ``ValueError``.
_READ_ERRORS = (
    OSError,
    EOFError,
    KeyError,
    SyntaxError,
    TypeError,
    RuntimeError,
    NotImplementedError,
    OverflowError,
    RecursionError,
    struct.error,
    zipfile.BadZipFile,
    zlib.error,
)


class ArrayHeader(NamedTuple):
    """What a member's ``.npy`` header declares, read without reading the data.

    Attributes:
        shape: the array's shape.
        dtype: its dtype.
    """

    shape: tuple[int, ...]
    dtype: np.dtype

    def describe(self) -> str:
        """``"float64 array of shape (9, 1, 4)"``."""
        return f"{self.dtype} array of shape {self.shape}"


def write_model_file(path: str | Path, metadata: dict[str, Any], arrays: dict[str, Any]) -> Path:
    """Write ``arrays`` and ``metadata`` (made JSON, with the format marker) to ``path``.

    ``.npz`` is appended when ``path`` has no suffix; parent folders are created.

    Returns:
        The path written.

    Raises:
        TypeError: ``path`` is not a ``str`` or ``os.PathLike``.
        ValueError: ``path`` has no file name (:func:`check_model_path`), or the arrays hold more
            than :data:`MAX_MODEL_BYTES` (the file would not load).
    """
    path = check_model_path(path)
    if not path.suffix:
        path = path.with_suffix(".npz")
    header = json.dumps({"format": FORMAT, "format_version": FORMAT_VERSION, **metadata})
    size = sum(np.asarray(value).nbytes for value in arrays.values()) + 4 * len(header)
    for what, taken, limit in (
        ("the arrays", size, "MAX_MODEL_BYTES"),
        ("the metadata", 4 * len(header), "MAX_METADATA_BYTES"),
    ):
        if taken > globals()[limit]:
            raise ValueError(
                f"cannot save to {path}: {what} take {_size(taken)}, over {limit} = "
                f"{_size(globals()[limit])} (delayed_rl.agents.common.save_util.{limit}): it would "
                "not load"
            )
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as file:
        np.savez_compressed(file, **arrays, metadata=np.array(header))
    return path


def check_model_path(path: Any) -> Path:
    """``path`` as a ``Path`` after checking that it can name a model file.

    Raises:
        TypeError: ``path`` is not a ``str`` or ``os.PathLike`` (e.g. ``None``, bytes, a number).
        ValueError: it has no file name (``""``, ``"."``, ``".."``, a path ending in ``/..``).
    """
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(
            f"path must be a str or os.PathLike naming a model file, got {path!r} "
            f"({type(path).__name__})"
        )
    checked = Path(path)
    if checked.name in ("", ".", ".."):
        raise ValueError(
            f"path must name a model file (e.g. 'model' or 'runs/model.npz'), got {str(path)!r}, "
            "which has no file name"
        )
    return checked


def resolve_model_path(path: str | Path) -> Path:
    """The model file ``path`` names, as ``load`` looks for it.

    In order: ``path`` as given; ``path`` + ``.npz``; ``path`` + ``.zip``; and for a ``path``
    ending in ``.zip`` or ``.npz``, the same name with the other suffix. So after SB3's
    ``EvalCallback`` saved ``best_model`` (written as ``best_model.npz``), both
    ``load("best_model")`` and SB3's ``load("best_model.zip")`` find it, and a
    ``CheckpointCallback`` file ``rl_model_10_steps.zip`` loads with or without its suffix.

    Raises:
        TypeError: ``path`` is not a ``str`` or ``os.PathLike``.
        ValueError: ``path`` has no file name (``""``, ``"."``: see :func:`check_model_path`).
        FileNotFoundError: none of them exists.
    """
    path = check_model_path(path)
    appended = [path.with_name(path.name + end) for end in _SUFFIXES if end != path.suffix]
    candidates = [path, *appended]
    if path.suffix in _SUFFIXES:
        candidates += [path.with_suffix(suffix) for suffix in _SUFFIXES if suffix != path.suffix]
    for candidate in candidates:
        if candidate.exists():
            return candidate
    others = ", ".join(candidate.name for candidate in candidates[1:])
    raise FileNotFoundError(f"no model file at {path} (nor {others})")


class ModelFile:
    """An open model file: its metadata and its arrays' headers, checked; arrays read on demand.

    Opening reads the archive's directory, every member's ``.npy`` header and the metadata; it
    checks that the archive is an ``.npz`` of plain (non-object) arrays whose declared sizes match
    their data and add up to at most :data:`MAX_MODEL_BYTES`, and that the metadata is this
    format's. No array data is read until :meth:`read`. Use it as a context manager.

    Args:
        path: the file.

    Attributes:
        where: the file's name, for messages.
        metadata: the metadata (a dict; its ``format`` and ``format_version`` checked).
        headers: the header of every array but the metadata, by name.

    Raises:
        ValueError: the file is not a readable ``.npz`` archive, holds objects or a member whose
            declared size does not match its data, is larger than the limits, has no metadata,
            or its metadata is not this format's (or of a newer version).
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.where = str(path)
        _check_container(self.path, self.where)
        try:
            self._zip = zipfile.ZipFile(self.path)
        except (ValueError, *_READ_ERRORS) as error:
            raise _unreadable(self.where, error) from None
        try:
            self._members = _members(self._zip, self.where)
            self.headers = {name: self._header(name) for name in self._members}
            self.metadata = self._read_metadata()
        except BaseException:
            self._zip.close()
            raise

    def __enter__(self) -> ModelFile:
        return self

    def __exit__(self, *exc_info: Any) -> None:
        self.close()

    def close(self) -> None:
        """Close the archive."""
        self._zip.close()

    def _header(self, name: str) -> ArrayHeader:
        info = self._members[name]
        try:
            with self._zip.open(info) as stream:
                version = npy.read_magic(stream)
                reader = _HEADER_READERS.get(version)
                if reader is None:
                    raise ValueError(f"unsupported .npy format version {version}")
                # numpy reads a header's declared length before checking it: check it first
                length = int.from_bytes(stream.read(2 if version == (1, 0) else 4), "little")
                if length > _MAX_NPY_HEADER:
                    raise ValueError(f"a .npy header of {length} bytes (at most {_MAX_NPY_HEADER})")
                stream.seek(0)
                npy.read_magic(stream)
                shape, _, dtype = reader(stream, max_header_size=_MAX_NPY_HEADER)
                offset = stream.tell()
        except (ValueError, *_READ_ERRORS) as error:
            raise _unreadable(self.where, error, name) from None
        if dtype.hasobject:
            raise ValueError(
                f"{self.where}: the array {name!r} holds Python objects (a pickle, which could "
                "run code): model files are read with allow_pickle=False"
            )
        if dtype.kind not in _KINDS or dtype.fields is not None or dtype.subdtype is not None:
            raise ValueError(
                f"{self.where}: the array {name!r} holds {dtype} values: model files hold plain "
                "numbers and text"
            )
        declared = math.prod(shape) * dtype.itemsize
        if declared != info.file_size - offset:
            raise ValueError(
                f"{self.where}: the array {name!r} declares shape {shape} of {dtype} "
                f"({_size(declared)}) but holds {_size(info.file_size - offset)} of data"
            )
        return ArrayHeader(tuple(shape), dtype)

    def _read_metadata(self) -> dict[str, Any]:
        header = self.headers.pop("metadata", None)
        if header is None or header.shape != () or header.dtype.kind != "U":
            raise ValueError(
                f"{self.where} is not a delayed-rl model file: it has no metadata string "
                f"(arrays: {sorted(self.headers)})"
            )
        if header.dtype.itemsize > MAX_METADATA_BYTES:
            raise ValueError(
                f"{self.where}: the metadata takes {_size(header.dtype.itemsize)}, over "
                f"MAX_METADATA_BYTES = {_size(MAX_METADATA_BYTES)}"
            )
        text = str(self._read_array("metadata"))
        try:
            metadata = json.loads(text)
        except (ValueError, RecursionError) as error:  # JSONDecodeError is a ValueError
            raise ValueError(f"{self.where}: the metadata is not valid JSON: {error}") from None
        if not isinstance(metadata, dict) or metadata.get("format") != FORMAT:
            raise ValueError(
                f"{self.where} is not a delayed-rl model file (its metadata lacks "
                f"format={FORMAT!r})"
            )
        version = metadata.get("format_version")
        if type(version) is not int or not 1 <= version <= FORMAT_VERSION:
            raise ValueError(
                f"{self.where} has model format version {version!r}; this delayed-rl reads "
                f"versions 1 to {FORMAT_VERSION} (upgrade delayed-rl for newer files)"
            )
        return metadata

    def read(self, names: Collection[str]) -> dict[str, np.ndarray]:
        """The arrays, which must be exactly ``names`` (check :attr:`headers` first).

        Raises:
            ValueError: an array is missing or unexpected, or its data is damaged.
        """
        missing, unexpected = set(names) - set(self.headers), set(self.headers) - set(names)
        if missing or unexpected:
            parts = [f"no {sorted(missing)} array" if missing else ""]
            parts.append(f"unexpected arrays {sorted(unexpected)}" if unexpected else "")
            raise ValueError(
                f"{self.where}: malformed model file: {'; '.join(p for p in parts if p)}"
            )
        return {name: self._read_array(name) for name in sorted(names)}

    def _read_array(self, name: str) -> np.ndarray:
        try:
            with self._zip.open(self._members[name]) as stream:
                return npy.read_array(stream, allow_pickle=False)
        except (ValueError, *_READ_ERRORS) as error:
            raise _unreadable(self.where, error, name) from None


def _check_container(path: Path, where: str) -> None:
    """Refuse what is not a small-directory zip archive before ``zipfile`` parses it.

    ``zipfile`` reads the whole central directory into memory (and objects per entry); a model
    file's is tiny, so a larger one, or a ZIP64 archive, is refused from its end record.
    """
    try:
        with open(path, "rb") as file:
            if file.read(6) == b"\x93NUMPY":
                raise ValueError(
                    f"{where} is not a delayed-rl model file: it holds a single .npy array, not "
                    "an .npz archive"
                )
            size = file.seek(0, 2)
            file.seek(max(0, size - 22 - 65_535))
            tail = file.read()
    except OSError as error:
        raise _unreadable(where, error) from None
    if size > MAX_MODEL_BYTES + _MAX_DIRECTORY_BYTES:
        raise ValueError(
            f"{where} takes {_size(size)} on disk, over MAX_MODEL_BYTES = "
            f"{_size(MAX_MODEL_BYTES)}: it is not a delayed-rl model file"
        )
    # zipfile's own search: an end record without a comment last, else the last one found
    at = len(tail) - 22
    if at < 0 or tail[at : at + 4] != b"PK\x05\x06" or tail[-2:] != b"\0\0":
        at = tail.rfind(b"PK\x05\x06")
    if at < 0 or len(tail) - at < 22:
        raise _unreadable(where, zipfile.BadZipFile("not a zip archive (no end record)"))
    directory = int.from_bytes(tail[at + 12 : at + 16], "little")
    zip64 = at >= 20 and tail[at - 20 : at - 16] == b"PK\x06\x07"
    if zip64 or directory > _MAX_DIRECTORY_BYTES:
        raise ValueError(
            f"{where} is not a delayed-rl model file: its archive directory is "
            f"{'a ZIP64 one' if zip64 else _size(directory)}, "
            "larger than any model file's"
        )


def _members(archive: zipfile.ZipFile, where: str) -> dict[str, zipfile.ZipInfo]:
    """The ``.npy`` members by array name, after checking their names, methods and sizes."""
    members: dict[str, zipfile.ZipInfo] = {}
    for info in archive.infolist():
        name = info.filename.removesuffix(".npy")
        if name == info.filename or name in members or not name:
            raise ValueError(
                f"{where} is not a delayed-rl model file: it holds a member {info.filename!r} "
                "(an .npz archive holds distinct NAME.npy members)"
            )
        if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
            raise ValueError(
                f"{where}: the member {info.filename!r} uses compression method "
                f"{info.compress_type} (model files are stored or deflated)"
            )
        if info.flag_bits & 0x1:
            raise ValueError(f"{where}: the member {info.filename!r} is encrypted")
        members[name] = info
    total = sum(info.file_size for info in members.values())
    if total > MAX_MODEL_BYTES:
        raise ValueError(
            f"{where}: its arrays would take {_size(total)} once decompressed, over "
            f"MAX_MODEL_BYTES = {_size(MAX_MODEL_BYTES)} (delayed_rl.agents.common.save_util."
            "MAX_MODEL_BYTES): refused before decompressing"
        )
    return members


def read_model_file(path: str | Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Read a model file: its metadata (format checked) and all its other arrays.

    Raises:
        ValueError: see :class:`ModelFile`.
    """
    with ModelFile(path) as model:
        return model.metadata, model.read(model.headers)


def _size(n: int) -> str:
    """``n`` bytes for people: ``"2.0 GiB"``, ``"512 B"``."""
    for unit, scale in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{n} B"


def _unreadable(where: str, error: BaseException, member: str | None = None) -> ValueError:
    part = "" if member is None else f" (array {member!r})"
    return ValueError(
        f"{where} is not a readable delayed-rl model file (.npz archive read with "
        f"allow_pickle=False){part}: {type(error).__name__}: {error}"
    )


def space_to_json(space: spaces.Discrete) -> dict[str, Any]:
    """A ``Discrete`` space as JSON."""
    return {"type": "Discrete", "n": int(space.n), "start": int(space.start)}


_INT64 = 2**63 - 1


def space_from_json(data: Any, name: str, where: str) -> spaces.Discrete:
    """The ``Discrete`` space that :func:`space_to_json` described.

    Raises:
        ValueError: ``data`` is not such a description, or its ``n`` and ``start`` are not
            integers with ``n >= 1`` and every element in the int64 range (the message names
            ``where`` and ``name``).
    """
    if (
        not isinstance(data, dict)
        or set(data) != {"type", "n", "start"}
        or data["type"] != "Discrete"
        or type(data["n"]) is not int
        or type(data["start"]) is not int
        or not 1 <= data["n"] <= _INT64
        or not -_INT64 - 1 <= data["start"] <= _INT64 - data["n"] + 1
    ):
        raise ValueError(f"{where}: malformed {name} in the metadata: {data!r}")
    return spaces.Discrete(data["n"], start=data["start"])
