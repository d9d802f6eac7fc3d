"""Reading a sweep file, YAML or JSON, with limits on what a hostile file can make the reader do.

A sweep file is a few dozen lines written by hand. :func:`read_sweep_file` refuses, before it
builds the Python objects, anything far beyond that: a file over :data:`MAX_SWEEP_FILE_BYTES`, values
nested over :data:`MAX_DEPTH` levels, over :data:`MAX_VALUES` values once YAML's aliases are
expanded or an alias inside the value it names, and a key given twice in one mapping. YAML is
read with PyYAML's safe loader (the ``sweep`` extra). The docs' sweeps page
(``docs/sweeps.md``) has the limits in full.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path
from typing import Any

__all__ = ["MAX_DEPTH", "MAX_SWEEP_FILE_BYTES", "MAX_VALUES", "read_sweep_file"]

MAX_SWEEP_FILE_BYTES = 1_000_000
"""The largest sweep file read (1 MB; the example sweep is under 2 kB)."""
MAX_DEPTH = 32
"""The deepest nesting of lists and mappings in a sweep file (the format itself needs 5)."""
MAX_VALUES = 100_000
"""The most values (numbers, strings, lists, mappings...) a sweep file holds, aliases expanded."""

_MERGE_TAG = "tag:yaml.org,2002:merge"


def read_sweep_file(path: str | Path) -> Any:
    """The content of a sweep file: YAML for ``.yaml``/``.yml``, JSON for ``.json``.

    Raises:
        OSError: the file cannot be read (e.g. there is none).
        ValueError: its suffix is none of those, it is larger than :data:`MAX_SWEEP_FILE_BYTES`, its
            text is not valid YAML or JSON, a mapping repeats a key, or it is nested deeper
            than :data:`MAX_DEPTH` or holds more than :data:`MAX_VALUES` values (aliases
            expanded); the message starts with the path and names the limit.
        RuntimeError: it is YAML and PyYAML (the ``sweep`` extra) is not installed.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".yaml", ".yml", ".json"):
        raise ValueError(f"a sweep file must end in .yaml, .yml or .json, got {str(path)!r}")
    with open(path, "rb") as handle:
        raw = handle.read(MAX_SWEEP_FILE_BYTES + 1)
    if len(raw) > MAX_SWEEP_FILE_BYTES:
        raise ValueError(
            f"{path} is larger than MAX_SWEEP_FILE_BYTES = {MAX_SWEEP_FILE_BYTES:,} bytes "
            "(delayed_rl.sweep.reading): a sweep file is a few dozen lines"
        )
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ValueError(f"{path} is not UTF-8 text: {error}") from None
    data = _read_json(path, text) if suffix == ".json" else _read_yaml(path, text)
    _check_size(path, data)
    return data


# ---------------------------------------------------------------------------------- JSON
def _unique_pairs(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object's pairs as a dict; a key given twice is a ``ValueError``."""
    mapping: dict[str, Any] = {}
    for key, value in pairs:
        if key in mapping:
            raise _DuplicateKey(key)
        mapping[key] = value
    return mapping


class _DuplicateKey(ValueError):
    """A JSON object gives ``key`` twice (carried out of ``json.loads`` to name the path)."""

    def __init__(self, key: str):
        super().__init__(key)
        self.key = key


def _read_json(path: Path, text: str) -> Any:
    try:
        return json.loads(text, object_pairs_hook=_unique_pairs)
    except _DuplicateKey as error:
        raise ValueError(
            f"{path} gives the key {error.key!r} twice in one object: give each key once"
        ) from None
    except RecursionError:
        raise ValueError(
            f"{path} is nested deeper than MAX_DEPTH = {MAX_DEPTH} levels "
            "(delayed_rl.sweep.reading)"
        ) from None
    except ValueError as error:  # json.JSONDecodeError, or an integer of too many digits
        raise ValueError(f"{path} is not valid JSON: {error}") from None


# ---------------------------------------------------------------------------------- YAML
def _read_yaml(path: Path, text: str) -> Any:
    try:
        import yaml
    except ImportError:
        raise RuntimeError(
            f"reading the YAML sweep file {path} needs PyYAML: pip install 'delayed-rl[sweep]' "
            "(or write the sweep as .json)"
        ) from None
    loader = None
    try:
        loader = _loader_class()(text)  # (its reader refuses control characters at once)
        loader.name = str(path)  # what PyYAML's messages call the text
        node = loader.get_single_node()  # composed within MAX_DEPTH; nothing constructed yet
        if node is None:
            return None
        _check_expansion(path, node, yaml)
        try:
            return loader.construct_document(node)
        except (ValueError, OverflowError) as error:  # an int of over 4300 digits, a bad date
            if isinstance(error, _Refused):
                raise
            raise ValueError(f"{path} is not valid YAML: {error}") from None
    except _Refused as error:
        raise ValueError(f"{path}, line {error.line}: {error}") from None
    except yaml.YAMLError as error:
        raise ValueError(f"{path} is not valid YAML: {' '.join(str(error).split())}") from None
    finally:
        if loader is not None:
            loader.dispose()


class _Refused(ValueError):
    """What the YAML loader refuses (a limit, a repeated key), at ``mark``'s line."""

    def __init__(self, mark: Any, message: str):
        super().__init__(message)
        self.line = mark.line + 1


@functools.cache
def _loader_class() -> type:
    """PyYAML's ``SafeLoader``, composing at most :data:`MAX_DEPTH` levels, refusing repeated keys.

    (Made on first use, so that PyYAML is imported only to read a YAML file.)
    """
    import yaml

    class SweepLoader(yaml.SafeLoader):
        depth = 0

        def compose_node(self, parent: Any, index: Any) -> Any:
            if self.depth >= MAX_DEPTH:
                raise _Refused(
                    self.peek_event().start_mark,
                    f"values nested deeper than MAX_DEPTH = {MAX_DEPTH} levels "
                    "(delayed_rl.sweep.reading)",
                )
            self.depth += 1
            try:
                return super().compose_node(parent, index)
            finally:
                self.depth -= 1

        def construct_mapping(self, node: Any, deep: bool = False) -> Any:
            if isinstance(node, yaml.MappingNode):
                seen: dict[Any, Any] = {}
                for key_node, _ in node.value:
                    if key_node.tag == _MERGE_TAG:
                        continue  # merged keys may be overridden: YAML's own rule
                    key = self.construct_object(key_node, deep=True)
                    try:
                        first = seen.setdefault(key, key_node)
                    except TypeError:
                        continue  # an unhashable key: the base class says so
                    if first is not key_node:
                        raise _Refused(
                            key_node.start_mark,
                            f"the key {key!r} is given a second time in one mapping (first at "
                            f"line {first.start_mark.line + 1}): give each key once",
                        )
            return super().construct_mapping(node, deep=deep)

    return SweepLoader


def _check_expansion(path: Path, root: Any, yaml: Any) -> None:
    """Refuse a node graph that stands for too much once its aliases are expanded.

    Too much is over :data:`MAX_VALUES` values, or scalars of over :data:`MAX_SWEEP_FILE_BYTES`
    characters in all (a long string repeated by aliases is as large as a long file once
    written out, as a run's configuration is), or a value that contains itself. Aliases make
    the composed graph a DAG whose nodes may be shared; a post-order walk without recursion
    counts each shared node once per use (memoized).
    """
    sizes: dict[int, tuple[int, int]] = {}  # per node: (values, characters), expanded
    on_path: set[int] = set()
    stack: list[tuple[Any, bool]] = [(root, False)]
    while stack:
        node, children_done = stack.pop()
        key = id(node)
        if children_done:
            on_path.discard(key)
            values, chars = 1, len(node.value) if isinstance(node, yaml.ScalarNode) else 0
            for child in _children(node, yaml):
                values, chars = values + sizes[id(child)][0], chars + sizes[id(child)][1]
            if values > MAX_VALUES or chars > MAX_SWEEP_FILE_BYTES:
                raise ValueError(
                    f"{path} stands for more than MAX_VALUES = {MAX_VALUES:,} values, or "
                    f"MAX_SWEEP_FILE_BYTES = {MAX_SWEEP_FILE_BYTES:,} characters, once its aliases are "
                    f"expanded (delayed_rl.sweep.reading): {_where(node)}"
                )
            sizes[key] = (values, chars)
            continue
        if key in sizes:
            continue
        on_path.add(key)
        stack.append((node, True))
        for child in _children(node, yaml):
            if id(child) in on_path:
                raise ValueError(
                    f"{path} holds a value that contains itself (an alias inside its own "
                    f"anchor's value): {_where(child)}"
                )
            if id(child) not in sizes:
                stack.append((child, False))


def _children(node: Any, yaml: Any) -> list[Any]:
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [part for pair in node.value for part in pair]
    return []


def _where(node: Any) -> str:
    return f"the value at line {node.start_mark.line + 1}, column {node.start_mark.column + 1}"


# ---------------------------------------------------------------------------------- both
def _check_size(path: Path, data: Any) -> None:
    """Refuse ``data`` nested over :data:`MAX_DEPTH` or of over :data:`MAX_VALUES` values."""
    count = 0
    stack = [(data, 1)]
    while stack:
        value, depth = stack.pop()
        count += 1
        if count > MAX_VALUES:
            raise ValueError(
                f"{path} holds more than MAX_VALUES = {MAX_VALUES:,} values "
                "(delayed_rl.sweep.reading)"
            )
        if isinstance(value, dict | list):
            if depth > MAX_DEPTH:
                raise ValueError(
                    f"{path} is nested deeper than MAX_DEPTH = {MAX_DEPTH} levels "
                    "(delayed_rl.sweep.reading)"
                )
            items = value.items() if isinstance(value, dict) else enumerate(value)
            stack.extend((item, depth + 1) for _, item in items)
