"""Whether a path given as a bag is one: the same one-line answer from every command."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

__all__ = [
    'BAG_SUFFIXES',
    'UNOPENED_HINT',
    'bag_directory',
    'inside_bag',
    'misnamed_output',
    'not_a_bag',
    'short_names',
]

#: files that make a directory a bag (rosbag2's storage files, plain or file-compressed)
BAG_SUFFIXES = ('.mcap', '.db3', '.mcap.zstd', '.db3.zstd')
#: files that are a bag on their own
_BAG_FILES = ('.mcap', '.db3', '.bag')


def _holds_bag_files(directory: Path) -> bool:
    if (directory / 'metadata.yaml').is_file():
        return True
    return any(any(directory.glob('*' + suffix)) for suffix in BAG_SUFFIXES)


#: said after rosbags' reason where a bag cannot be opened
UNOPENED_HINT = '(damaged, cut short, or not a bag?)'


def not_a_bag(path: Path) -> str | None:
    """Why ``path`` cannot be a bag (the message, with the path), or None if it may be one.

    A missing path; a directory with neither ``metadata.yaml`` nor storage files, and among
    those a folder of bags (the user gave its parent: name the bags instead). Files are left
    to the readers, which know their formats.
    """
    if not path.exists():
        return f'{path}: no such bag'
    if not path.is_dir() or _holds_bag_files(path):
        return None
    inside = sorted(
        p.name
        for p in path.iterdir()
        if (p.is_dir() and _holds_bag_files(p)) or (p.is_file() and p.suffix in _BAG_FILES)
    )
    if inside:
        return (
            f'{path}: a folder of {len(inside)} bag{"s" if len(inside) > 1 else ""} '
            f'({", ".join(inside[:3])}{", ..." if len(inside) > 3 else ""}), not a bag: '
            f'name the bags (e.g. {path / inside[0]})'
        )
    return (
        f'{path}: not a bag (no metadata.yaml, .mcap or .db3 files in this directory; '
        'expected a rosbag2 directory, .mcap, .db3, .bag)'
    )


def bag_directory(path: Path) -> Path | None:
    """The rosbag2 directory ``path`` is or belongs to, or None (a bag file on its own).

    A directory given as a bag is one; a file is part of one where its directory holds a
    ``metadata.yaml`` (``run/run_0.mcap``).
    """
    if path.is_dir():
        return path
    if (path.parent / 'metadata.yaml').is_file():
        return path.parent
    return None


def inside_bag(output: Path, in_bag: Path) -> str | None:
    """Why ``output`` may not be written where it is (the message), or None if it may.

    An output inside the input's rosbag2 directory would be read as part of that bag
    afterwards (readers take the data files present, listed in ``metadata.yaml`` or not).
    """
    bag_dir = bag_directory(in_bag)
    if bag_dir is None:
        return None
    inside, where = bag_dir.resolve(), output.resolve()
    if where != inside and inside not in where.parents:
        return None
    return (
        f'{output}: inside the input bag directory {bag_dir} (read as part of that bag '
        'afterwards); write it elsewhere, e.g. beside the bag directory'
    )


#: the suffix that names a bag of each storage format
FORMAT_SUFFIX = {'mcap': '.mcap', 'sqlite3': '.db3', 'ros1': '.bag'}


def misnamed_output(output: Path, fmt: str) -> str | None:
    """Why ``output`` may not name a bag of format ``fmt`` (the message), or None if it may.

    A name ending in another format's suffix is refused: ``out.db3`` for an MCAP output would
    be a rosbag2 directory named like an sqlite3 file, holding ``out.db3.mcap``. A ROS 1 bag
    is a single file that readers know by its ``.bag`` suffix: a name without it is refused
    too (``out`` was written, and then no reader, rosbags' or this package's, opened it).
    """
    suffix, want = output.suffix.lower(), FORMAT_SUFFIX[fmt]
    if suffix in FORMAT_SUFFIX.values() and suffix != want:
        return (
            f"-o {output}: a {suffix} name, but the output has the input's format ({fmt}, "
            f'{want}): name it {output.with_suffix(want).name}'
            + ('' if fmt == 'ros1' else ' or without a suffix (a rosbag2 directory)')
        )
    if fmt == 'ros1' and output.suffix != want:  # readers match it exactly: not .BAG either
        fixed = (
            output.with_suffix(want) if suffix == want else output.with_name(output.name + want)
        )
        return f'-o {output}: a ROS 1 bag is known by its {want} suffix: name it {fixed.name}'
    return None


def short_names(paths: Sequence[Path]) -> list[str]:
    """Each bag's name in a table, unique among ``paths``: its own, or with parent folders.

    ``u1/cycle_1`` and ``u2/cycle_1`` for two bags both named ``cycle_1`` (a table of their
    names alone would not tell them apart), others by their names; the same bag given twice
    keeps one name.
    """
    full = [p.resolve() for p in paths]
    depth = [1] * len(full)

    def name(k: int) -> str:
        return paths[k].name if depth[k] == 1 else '/'.join(full[k].parts[-depth[k] :])

    for _ in range(64):
        owners: dict[str, set[Path]] = {}
        for k in range(len(full)):
            owners.setdefault(name(k), set()).add(full[k])
        clashing = [k for k in range(len(full)) if len(owners[name(k)]) > 1]
        if not clashing:
            break
        for k in clashing:
            depth[k] += 1
    return [name(k) for k in range(len(full))]
