"""Reading the files a user hands sctd, trusting nothing of them: one strict, bounded
reader for every file the project reads (skills and their model files, input mapping
files, device scripts, configs).

- **Regular files only, size-capped before reading.** A device (``/dev/zero``,
  ``/dev/urandom``), a FIFO or a directory is refused by what ``fstat`` says of the
  opened file, before a byte is read; a regular file larger than its cap is refused
  with the cap in the error, and no more than the cap is ever read (a file that grows
  while it is read is refused too).
- **Inside a folder, when asked.** A path that must stay inside a folder (a skill's
  model files) is resolved, symlinks included, and refused when it leaves the folder;
  the refusal names the path, never the content.
- **UTF-8 text**, or an error naming the first bad byte's offset.
- **Strict, bounded YAML.** Safe YAML (libyaml where present) that refuses duplicate
  mapping keys (plain loaders keep the last of two equal keys: ``enable: 10, enable:
  null`` would hold a deadman), recursive aliases, documents whose aliases expand to
  more than ``max_nodes`` nodes (a "billion laughs" is a few hundred bytes), and nesting
  deeper than ``max_depth``.

Errors are :class:`FileError` (a ``ValueError``) with the file, the place in it and
the problem, read as ``file: where: problem``; callers re-raise them as their own kind.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Any, BinaryIO

import yaml

MAX_YAML_BYTES = 1024 * 1024  # a mapping file, a script, a config: far below this
MAX_NODES = 100_000  # YAML nodes after expanding aliases
MAX_DEPTH = 64  # YAML nesting


class FileError(ValueError):
    """A file sctd will not read, or will not take as it is: ``file: where: problem``."""

    def __init__(self, file: str, where: str, problem: str):
        self.file, self.where, self.problem = file, where, problem
        super().__init__(f"{file}: {where}: {problem}" if where else f"{file}: {problem}")


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISFIFO, "a FIFO"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def inside(path: str | Path, folder: str | Path, file: str, where: str = "") -> Path:
    """``path`` resolved (symlinks followed); FileError when that leaves ``folder``."""
    real, root = Path(os.path.realpath(path)), Path(os.path.realpath(folder))
    if real != root and root not in real.parents:
        raise FileError(file, where, f"{os.fspath(path)!r} resolves outside {os.fspath(folder)!r}")
    return real


def open_regular(path: str | Path, limit: int, file: str | None = None, where: str = "") -> BinaryIO:
    """A regular file of at most ``limit`` bytes, opened for reading (for files read as
    a stream: the caller bounds what it keeps)."""
    name = os.fspath(path) if file is None else file
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as e:
        raise FileError(name, where, f"cannot open ({e.strerror})") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise FileError(name, where, f"{_kind(st.st_mode)}, not a regular file")
        if st.st_size > limit:
            raise FileError(name, where, f"{st.st_size} bytes, more than the {limit} allowed")
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_bytes(path: str | Path, limit: int, file: str | None = None, where: str = "") -> bytes:
    """A regular file's bytes, at most ``limit`` of them (module doc).

    ``file`` and ``where`` name it in errors (default: the path itself).
    """
    name = os.fspath(path) if file is None else file
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as e:
        raise FileError(name, where, f"cannot open ({e.strerror})") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise FileError(name, where, f"{_kind(st.st_mode)}, not a regular file")
        if st.st_size > limit:
            raise FileError(name, where, f"{st.st_size} bytes, more than the {limit} allowed")
        chunks, n = [], 0
        while n <= limit:
            chunk = os.read(fd, min(1 << 20, limit + 1 - n))
            if not chunk:
                break
            chunks.append(chunk)
            n += len(chunk)
        if n > limit:
            raise FileError(name, where, f"grew past the {limit} bytes allowed while read")
        return b"".join(chunks)
    except OSError as e:
        raise FileError(name, where, f"cannot read ({e.strerror})") from None
    finally:
        os.close(fd)


def decode_text(data: bytes, file: str, where: str = "") -> str:
    """UTF-8 text, or FileError naming the first byte that is not."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise FileError(file, where, f"not UTF-8 text (byte {e.start})") from None


def read_text(path: str | Path, limit: int, file: str | None = None, where: str = "") -> str:
    """A regular file (at most ``limit`` bytes) as UTF-8 text."""
    name = os.fspath(path) if file is None else file
    return decode_text(read_bytes(path, limit, name, where), name, where)


# --- YAML -------------------------------------------------------------------------------


class StrictLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]
    """Safe YAML (libyaml's parser where present) that refuses duplicate mapping keys."""


def _mapping_without_duplicates(loader: Any, node: yaml.MappingNode, deep: bool = False) -> Any:
    loader.flatten_mapping(node)
    seen = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=True)
        try:
            duplicate = key in seen
            seen.add(key)
        except TypeError:  # unhashable: construct_mapping names it
            continue
        if duplicate:
            raise yaml.constructor.ConstructorError(
                "while constructing a mapping", node.start_mark, f"duplicate key {key!r}",
                key_node.start_mark)
    return loader.construct_mapping(node, deep=deep)


StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping_without_duplicates)


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [n for pair in node.value for n in pair]
    return []


def _line(node: yaml.Node) -> str:
    return f"line {node.start_mark.line + 1}"


def check_bounds(root: yaml.Node, file: str, max_nodes: int = MAX_NODES, max_depth: int = MAX_DEPTH) -> None:
    """Refuse a composed YAML document that nests deeper than ``max_depth``, whose
    aliases refer back to themselves, or that expands to more than ``max_nodes`` nodes
    (each use of an alias counts its whole subtree): iterative, and linear in the
    document's distinct nodes."""
    size: dict[int, int] = {}  # id(node) -> nodes below it, expanded, itself included
    open_: set[int] = set()
    stack: list[tuple[yaml.Node, int, bool]] = [(root, 1, False)]
    while stack:
        node, depth, done = stack.pop()
        key = id(node)
        if done:
            open_.discard(key)
            total = 1 + sum(size[id(c)] for c in _children(node))
            if total > max_nodes:
                raise FileError(file, _line(node), f"aliases expand to more than {max_nodes} nodes")
            size[key] = total
            continue
        if key in size:
            continue
        if key in open_:
            raise FileError(file, _line(node), "an alias refers to the node that contains it")
        if depth > max_depth:
            raise FileError(file, _line(node), f"nested deeper than {max_depth} levels")
        open_.add(key)
        stack.append((node, depth, True))
        stack.extend((c, depth + 1, False) for c in _children(node) if id(c) not in size)


def parse_yaml(text: str, file: str, max_nodes: int = MAX_NODES, max_depth: int = MAX_DEPTH) -> Any:
    """One YAML document, strict and bounded (module doc); an empty one is None."""
    loader = StrictLoader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        check_bounds(node, file, max_nodes, max_depth)
        return loader.construct_document(node)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise FileError(file, where, f"invalid YAML ({problem})") from None
    except RecursionError:
        raise FileError(file, "", "invalid YAML (nested too deeply)") from None
    finally:
        loader.dispose()


def load_yaml(path: str | Path, limit: int = MAX_YAML_BYTES, file: str | None = None,
              max_nodes: int = MAX_NODES, max_depth: int = MAX_DEPTH) -> Any:
    """A YAML file: regular, at most ``limit`` bytes, UTF-8, strict and bounded."""
    name = os.fspath(path) if file is None else file
    return parse_yaml(read_text(path, limit, name), name, max_nodes, max_depth)
