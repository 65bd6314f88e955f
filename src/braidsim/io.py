"""Whole-or-nothing file output: write to a temporary name, then rename.

Every file braidsim writes goes through here, so an interrupted run never leaves a
half-written output behind.
"""

from __future__ import annotations

import math
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any


def _umask() -> int:
    # os.umask can only be read by setting it; put it straight back
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


_UMASK = _umask()
#: permissions of written files and directories: what open() / mkdir() would give
FILE_MODE = 0o666 & ~_UMASK
DIR_MODE = 0o777 & ~_UMASK


def _prefix(p: Path) -> str:
    """Prefix of the hidden temporaries beside ``p``; it holds our process id so that a later
    run can remove the ones a killed process left (:func:`remove_stale`)."""
    return f".{p.name}.braidsim-{os.getpid()}-"


def process_gone(pid: int) -> bool:
    """Whether process ``pid`` no longer exists (one we may not signal exists): the test
    of the hidden temporaries that a killed braidsim left behind."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        pass
    return False


def _stale_temporary(name: str) -> bool:
    """Whether ``name`` is a hidden temporary (:func:`_prefix`) of a braidsim process that
    is gone."""
    m = re.fullmatch(r"\..+\.braidsim-(\d+)-.*", name)
    return m is not None and process_gone(int(m.group(1)))


def remove_stale(p: Path) -> int:
    """Remove the hidden temporaries beside ``p`` left by braidsim processes that are gone
    (killed before they could clean up); return how many."""
    pat = re.compile(re.escape(f".{p.name}.braidsim-") + r"(\d+)-.*")
    n = 0
    try:
        entries = list(p.parent.iterdir())
    except OSError:
        return 0
    for e in entries:
        m = pat.fullmatch(e.name)
        if m is None:
            continue
        if not process_gone(int(m.group(1))):
            continue  # alive (or not ours to signal): another braidsim is writing
        if e.is_dir() and not e.is_symlink():
            shutil.rmtree(e, ignore_errors=True)
        else:
            e.unlink(missing_ok=True)
        n += 1
    return n


def check_output_target(
    path: str | Path, option: str, directory: bool, suffixes: tuple[str, ...] = ()
) -> None:
    """Refuse an output path that cannot be written, before any work starts.

    Checks that ``path`` is not an existing entry of the other kind (a file where a directory
    is written, or the reverse), that its nearest existing ancestor is a writable directory
    (not a file, not read-only: a file can be created and removed there), and, for files,
    that the name ends with one of ``suffixes``. Missing folders above ``path`` are allowed:
    the writers create them.

    Raises
    ------
    InputError
        One line naming ``option``, the path and what is allowed.
    """
    from braidsim.errors import InputError

    p = Path(path)
    what = "a directory" if directory else "a file"
    if suffixes and (directory or p.suffix.lower() not in suffixes):
        raise InputError(
            f"{option}: {str(p)!r} has no known extension; allowed {', '.join(suffixes)}"
        )
    try:
        _check_target(p, option, directory, what)
    except OSError as exc:  # a name too long, a loop of links: the path itself is refused
        why = exc.strerror or exc.__class__.__name__
        raise InputError(
            f"{option}: {shown_path(p)!r} cannot be used as a path ({why}); allowed {what} "
            "path the file system takes (names of at most 255 bytes a part)"
        ) from None


def shown_path(path: str | Path) -> str:
    """``path`` for a one-line message: whole up to 60 characters, else its first 40 and
    last 12 around an ellipsis (a name of 300 characters would fill the terminal)."""
    text = str(path)
    return text if len(text) <= 60 else f"{text[:40]}...{text[-12:]}"


def _check_target(p: Path, option: str, directory: bool, what: str) -> None:
    """The checks of :func:`check_output_target` after the extension's."""
    from braidsim.errors import InputError

    if p.is_symlink() and not p.exists():
        raise InputError(f"{option}: {str(p)!r} is a broken link; allowed {what} path")
    p = _target(p)  # the writers follow a link: its target is what they replace
    if p.exists():
        if directory and not p.is_dir():
            raise InputError(f"{option}: {str(p)!r} exists and is not a directory; allowed {what}")
        if not directory and p.is_dir():
            raise InputError(f"{option}: {str(p)!r} is a directory; allowed {what} path")
        if not os.access(p, os.W_OK):
            raise InputError(f"{option}: {str(p)!r} is not writable; allowed a writable {what}")
    parent = p.parent
    while not parent.exists():
        if parent.is_symlink():
            raise InputError(f"{option}: {str(parent)!r} is a broken link; allowed {what} path")
        parent = parent.parent
    if not parent.is_dir():
        raise InputError(
            f"{option}: {str(p)!r} is under {str(parent)!r}, which is not a directory; "
            f"allowed {what} in a directory"
        )
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(
            f"{option}: {str(parent)!r} is not writable (read-only or not ours), so "
            f"{str(p)!r} cannot be written; allowed a writable location"
        )
    # os.access answers from the mode bits, and for root it says yes almost everywhere:
    # /proc, a read-only mount or a full disk would only fail at the end of the work, under
    # a temporary's name. Creating a file where the output (or its missing folders) will
    # be made is the test that matches the write.
    try:
        fd, probe = tempfile.mkstemp(prefix=_prefix(p), suffix=".probe", dir=parent)
    except OSError as exc:
        why = exc.strerror or exc.__class__.__name__
        raise InputError(
            f"{option}: {str(p)!r} cannot be written: creating a file in {str(parent)!r} "
            f"fails ({why}); allowed a writable location"
        ) from None
    os.close(fd)
    Path(probe).unlink(missing_ok=True)


@contextmanager
def signals_deferred() -> Iterator[None]:
    """Hold SIGINT, SIGTERM and SIGHUP back within the block, then let them in.

    For the renames that put an output in place and record it (:data:`WRITTEN`): a signal
    between two of them would leave an earlier output aside under a hidden name, or a
    written output unnamed. Within the block each of those signals is only noted, by a
    handler of its own; after it the handlers that were there come back and a signal that
    came is raised again, for them. (Blocking the signals in this thread instead does not
    hold them in a process with other threads: the kernel hands the signal to one of them,
    and Python runs its handler in the main thread all the same.) Outside the main thread,
    where Python sets no handlers, the block runs as it is."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    came: list[int] = []

    def note(signum: int, frame: Any) -> None:
        came.append(signum)

    # (a handler set outside Python, which getsignal gives as None, is left in place: it
    # could not be set back)
    held = [
        sig
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
        if signal.getsignal(sig) is not None
    ]
    before = [signal.signal(sig, note) for sig in held]
    try:
        yield
    finally:
        for sig, handler in zip(held, before, strict=True):
            signal.signal(sig, handler)
        if came:
            signal.raise_signal(came[0])


#: every output put in place by this process, in order (the command line reports them when
#: a signal arrives after an output was already whole)
WRITTEN: list[Path] = []


def _target(path: str | Path) -> Path:
    """The path an output replaces: a symbolic link's target (the link itself stays), else
    ``path``."""
    p = Path(path)
    return p.resolve() if p.is_symlink() else p


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder + rename);
    a symbolic link at ``path`` is followed."""
    return atomic_write_with(path, lambda tmp: tmp.write_bytes(data))


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Text version of :func:`atomic_write_bytes` (UTF-8)."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_with(path: str | Path, writer: Callable[[Path], object]) -> Path:
    """Let ``writer(tmp_path)`` produce a file (e.g. ``fig.savefig``), then rename it into
    place; a symbolic link at ``path`` is followed."""
    p = _target(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    remove_stale(p)
    fd, tmp = tempfile.mkstemp(prefix=_prefix(p), suffix=p.suffix, dir=p.parent)
    os.close(fd)
    try:
        writer(Path(tmp))
        os.chmod(tmp, FILE_MODE)  # mkstemp makes 0600; outputs are ordinary files
        with signals_deferred():  # renamed into place is written: it is named as such
            os.replace(tmp, p)
            WRITTEN.append(p)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        raise _named(exc, tmp, p) from None
    return p


def _named(exc: BaseException, tmp: str | Path, path: Path, unnamed: bool = True) -> BaseException:
    """``exc``, or for an I/O error about the temporary ``tmp`` or a file under it (or, with
    ``unnamed``, about no file: a writer that wrote to a file object), the same error about
    ``path`` or the file under it: the message names the output the user asked for, not a
    hidden name."""
    if not isinstance(exc, OSError):
        return exc
    name = exc.filename
    if (name is None and unnamed) or (name is not None and os.fspath(name) == os.fspath(tmp)):
        where = str(path)
    elif isinstance(name, str) and name.startswith(os.fspath(tmp) + os.sep):
        where = str(path) + name[len(os.fspath(tmp)) :]
    else:
        return exc
    return OSError(exc.errno, exc.strerror or str(exc), where)


#: the file that marks a folder as braidsim's output: its kind on the first line, then
#: :data:`WRITTEN_HEADER` and every file and folder braidsim wrote in it, one relative path
#: (``/``-separated) a line. A marker of only its kind (an output of a braidsim that did not
#: list) stands, as it did then, for an output whose content is all braidsim's
MARKER = ".braidsim-output"
WRITTEN_HEADER = (
    "# written by braidsim, relative to this folder (a re-run replaces the folder only "
    "while it holds nothing else):"
)
#: the command that writes each kind of output directory whose kind is not its name
OUTPUT_COMMANDS = {
    "machine report": "machine",
    "design report": "design",
    "paper report": "paper",
    "continuation": "continue",
}


@contextmanager
def atomic_directory(path: str | Path, kind: str = "output") -> Iterator[Path]:
    """Build a whole output directory under a temporary name, then rename it into place.

    Yields the temporary directory (a sibling of ``path``, so the final rename stays on one
    file system). On success a marker file (:data:`MARKER`) naming ``kind`` and listing
    every file and folder written is added and the directory is renamed to ``path``; a
    previous output of the same kind at ``path`` is replaced, unless it holds something
    braidsim did not write there (:func:`check_output_directory`). On any
    error the temporary directory is removed and ``path`` is left as it was: the output is
    complete or absent, never half-written. A symbolic link at ``path`` is followed: its
    target is the output replaced.

    Raises
    ------
    InputError
        ``path`` exists and is not an empty directory or an earlier output of ``kind``
        holding only what braidsim wrote (we never delete what we did not write).
    """
    p = _target(path)
    check_output_directory(p, kind)
    p.parent.mkdir(parents=True, exist_ok=True)
    remove_stale(p)
    tmp = Path(tempfile.mkdtemp(prefix=_prefix(p), suffix=".tmp", dir=p.parent))
    mark = len(WRITTEN)  # the files written inside are parts of this output, not outputs
    old: Path | None = None
    swapped = False
    try:
        yield tmp
        listed = "".join(f"{rel}\n" for rel in _entries(tmp))
        (tmp / MARKER).write_text(f"{kind}\n{WRITTEN_HEADER}\n{listed}", encoding="utf-8")
        os.chmod(tmp, DIR_MODE)  # mkdtemp makes 0700
        if p.exists():
            check_output_directory(p, kind)
            old = Path(tempfile.mkdtemp(prefix=_prefix(p), suffix=".old", dir=p.parent))
        # the swap is one step for a signal: between its renames the earlier output lies
        # aside under a hidden name, and the new one is not yet named as written
        with signals_deferred():
            if old is not None:
                os.replace(p, old / p.name)
                try:
                    os.replace(tmp, p)
                except BaseException:
                    os.replace(old / p.name, p)  # the earlier output stays
                    raise
            else:
                os.replace(tmp, p)
            del WRITTEN[mark:]
            WRITTEN.append(p)
            swapped = True
    except BaseException as exc:
        if not swapped:  # (a signal held back by the swap is raised after it: p is whole)
            shutil.rmtree(tmp, ignore_errors=True)
            del WRITTEN[mark:]
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        named = _named(exc, tmp, p, unnamed=False)
        if named is exc:
            raise
        raise named from None
    if old is not None:
        try:
            shutil.rmtree(old, ignore_errors=True)
        except BaseException:  # a signal: the earlier output is still removed
            shutil.rmtree(old, ignore_errors=True)
            raise


def _entries(
    folder: Path, keep: Callable[[str], bool] = lambda rel: True, prefix: str = ""
) -> Iterator[str]:
    """The files and folders under ``folder``, as ``/``-separated paths relative to it
    (after ``prefix``), sorted, each folder before its content; links are not followed, and
    a folder ``keep`` refuses is named but not entered. The folder's own marker is left
    out."""
    for entry in sorted(folder.iterdir(), key=lambda e: e.name):
        if not prefix and entry.name == MARKER:
            continue
        rel = prefix + entry.name
        yield rel
        if keep(rel) and entry.is_dir() and not entry.is_symlink():
            yield from _entries(entry, keep, rel + "/")


def _read_marker(folder: Path) -> tuple[str, set[str] | None] | None:
    """The kind and the listed paths of the marker in ``folder`` (None for a marker that
    lists none), or None when it has no readable marker."""
    marker = folder / MARKER
    try:
        if not marker.is_file():
            return None
        lines = marker.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError):
        return None
    if len(lines) > 1 and lines[1] == WRITTEN_HEADER:
        return lines[0].strip(), set(lines[2:])
    if len(lines) == 1:  # an earlier braidsim's: its kind only
        return lines[0].strip(), None
    return None


def _not_written_by_us(folder: Path, listed: set[str]) -> str | None:
    """The first path under ``folder`` that braidsim did not write there (not in
    ``listed``, nor a hidden temporary of a braidsim process that is gone), or None."""

    def ours(rel: str) -> bool:
        return rel in listed or _stale_temporary(rel.rsplit("/", 1)[-1])

    for rel in _entries(folder, keep=ours):
        if not ours(rel):
            return rel
    return None


def check_output_directory(path: str | Path, kind: str = "output") -> None:
    """Raise :class:`InputError` unless ``path`` is absent, an empty directory, or an earlier
    output of ``kind`` (marked by :data:`MARKER`) that holds only what braidsim wrote in it:
    a file or folder of the user's in it (``notes.txt``, another command's ``--out``) would
    be deleted with the output it replaces."""
    from braidsim.errors import InputError

    p = Path(path)
    check_output_target(p, "--out", directory=True)
    if not p.exists():
        return
    if not p.is_dir():
        raise InputError(
            f"--out: {str(p)!r} exists and is not a directory; allowed: a new or empty directory"
        )
    if not any(p.iterdir()):
        return
    marked = _read_marker(p)
    # the marker holds the kind, which earlier outputs keep; the message names the command
    verb = OUTPUT_COMMANDS.get(kind, kind.removeprefix("analysis-"))  # "analysis-<verb>"
    if marked is None or marked[0] != kind:
        raise InputError(
            f"--out: {str(p)!r} is not empty and is not an earlier output of `braidsim {verb}`; "
            "allowed: a new or empty directory, or an earlier output to replace"
        )
    listed = marked[1]
    foreign = None if listed is None else _not_written_by_us(p, listed)
    if foreign is not None:
        raise InputError(
            f"--out: {str(p)!r} is an earlier output of `braidsim {verb}`, but "
            f"{str(p / foreign)!r} in it was not written there by braidsim and would be "
            "deleted with it; move that out of the folder, or choose another --out"
        )


def json_safe(obj: Any) -> Any:
    """``obj`` as strict JSON data: NaN and inf become None (null), numpy arrays lists and
    numpy scalars Python numbers, tuples lists; mappings and sequences are walked through."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, Mapping):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v) for v in obj]
    if getattr(obj, "ndim", 0) and hasattr(obj, "tolist"):  # a numpy array (not 0-d)
        return json_safe(obj.tolist())
    if hasattr(obj, "item") and callable(obj.item):  # a numpy scalar or 0-d array
        return json_safe(obj.item())
    return obj
