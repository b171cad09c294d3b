"""Output files: checked before any work, written all-or-nothing, temporaries that never outlive a run.

* :func:`check_output_path` refuses an output path that cannot be written (empty, a folder, a
  path through a file, a name too long, a folder that is not writable) with an
  :class:`~pwas_hdl.errors.InputError` -- called before the work starts.
* :class:`OutputSet` is the transaction of one command: every output path is added (and checked,
  also against the others and against the command's inputs) first; the contents are staged in
  temporary files in the target folders; on success they are renamed into place, on any error
  (or ``SIGTERM``, see :func:`install_termination_handler`) the temporaries are removed and no
  target is touched.
* Temporaries are named ``.<name>.pwas-tmp-<pid>-<random>``: a run that was killed outright
  (``SIGKILL``, power loss) leaves them behind, and the next run that writes into that folder
  removes those whose process is gone (:func:`clean_stale_temps`).
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterable, Iterator

from pwas_hdl.errors import InputError, ToolFailed

__all__ = [
    "atomic_write_text",
    "atomic_write_bytes",
    "check_output_path",
    "OutputSet",
    "clean_stale_temps",
    "make_temp_dir",
    "logs_kept",
    "KEPT_LOGS",
    "install_termination_handler",
    "TEMP_MARK",
]

#: Marks the temporary files and folders of pwas-hdl (followed by the pid of the process).
TEMP_MARK = ".pwas-tmp-"
_TEMP_RE = re.compile(r"^\..*" + re.escape(TEMP_MARK) + r"(\d+)-[A-Za-z0-9_]+(?:\.tmp)?$")


# ------------------------------------------------------------------------------------------ temporaries
def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        return True
    except OSError:
        return True
    return True


def clean_stale_temps(folder: str | os.PathLike) -> list[Path]:
    """Remove the pwas-hdl temporaries in ``folder`` whose process no longer runs.

    Parameters
    ----------
    folder : path
        Folder to scan (not recursively); an unreadable folder is skipped. Temporaries are the
        names with :data:`TEMP_MARK` and a process id; removal errors are ignored.

    Returns
    -------
    list of Path
        What was removed (nothing that a live process may still use).
    """
    removed: list[Path] = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        m = _TEMP_RE.match(entry.name)
        if not m or _pid_alive(int(m.group(1))):
            continue
        path = Path(entry.path)
        try:
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(path)
            else:
                path.unlink()
            removed.append(path)
        except OSError:
            pass
    return removed


def _temp_prefix(name: str) -> str:
    return f".{name[:80]}{TEMP_MARK}{os.getpid()}-"


def make_temp_dir(parent: str | os.PathLike, name: str) -> Path:
    """A new temporary folder in ``parent`` for the output ``name`` (stale ones are cleaned first).

    Parameters
    ----------
    parent : path
        Existing folder that will hold it (the output's own folder, so that a rename publishes it).
    name : str
        The output's file name (its first 80 characters go into the hidden temporary name).

    Returns
    -------
    Path
        The new, empty folder ``.<name>.pwas-tmp-<pid>-<random>``.
    """
    clean_stale_temps(parent)
    return Path(tempfile.mkdtemp(prefix=_temp_prefix(name), dir=parent))


@contextmanager
def logs_kept(folder: str | os.PathLike | None, name: str) -> Iterator[None]:
    """Around a tool run in the temporary ``folder`` (removed afterwards; None: nothing to do): a
    :class:`~pwas_hdl.errors.ToolFailed` whose log is inside it is raised again with the log copied
    out to ``$TMPDIR/NAME-XXXX.log``, so that the file its ``error:`` line names still exists.
    Of those logs the newest :data:`KEPT_LOGS` of each ``NAME`` stay; older ones are removed.

    Parameters
    ----------
    folder : str or os.PathLike, optional
        The tool run's temporary folder; None: the context does nothing.
    name : str
        ``NAME``, the prefix of the kept log's file name (e.g. the tool's name).

    Yields
    ------
    None
        The body of the ``with`` block runs once.

    Raises
    ------
    ToolFailed
        Raised again, with :attr:`~pwas_hdl.errors.ToolFailed.log` the kept copy (or None where it
        could not be copied), when the original log is inside ``folder``.
    """
    try:
        yield
    except ToolFailed as exc:
        if folder is None or exc.log is None or Path(folder).resolve() not in Path(exc.log).resolve().parents:
            raise
        kept = None
        try:
            if Path(exc.log).is_file():
                _prune_kept_logs(name, KEPT_LOGS - 1)
                fd, kept = tempfile.mkstemp(prefix=f"{name}-", suffix=".log")
                os.close(fd)
                shutil.copyfile(exc.log, kept)
        except OSError:  # the log cannot be kept: the message without it (-v still prints its end)
            if kept is not None:
                Path(kept).unlink(missing_ok=True)
            kept = None
        raise type(exc)(exc.message, kept, exc.tail) from None


#: How many logs of failed tool runs :func:`logs_kept` keeps in ``$TMPDIR`` per name (the newest).
KEPT_LOGS = 20


def _prune_kept_logs(name: str, keep: int) -> None:
    """Remove all but the newest ``keep`` of ``$TMPDIR/NAME-*.log`` (plain files of the pattern
    :func:`logs_kept` writes; a file that cannot be removed is left)."""
    pat = re.compile(re.escape(name) + r"-[a-z0-9_]{8}\.log")  # mkstemp's 8 random characters, nothing else
    found = []
    try:
        with os.scandir(tempfile.gettempdir()) as it:
            for e in it:
                if pat.fullmatch(e.name) and e.is_file(follow_symlinks=False):
                    try:
                        found.append((e.stat(follow_symlinks=False).st_mtime, e.path))
                    except OSError:
                        pass
    except OSError:
        return
    for _, path in sorted(found, reverse=True)[max(keep, 0):]:
        try:
            os.unlink(path)
        except OSError:
            pass


def _make_temp_file(parent: Path, name: str) -> Path:
    clean_stale_temps(parent)
    fd, tmp = tempfile.mkstemp(prefix=_temp_prefix(name), suffix=".tmp", dir=parent)
    os.close(fd)
    return Path(tmp)


def _publish(tmp: Path, target: Path) -> None:
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    os.replace(tmp, target)


def _publish_dir(tmp: Path, target: Path) -> None:
    """Put the staged folder ``tmp`` in place of ``target`` (an old ``target`` folder is moved aside, then removed)."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)
    old = None
    if target.is_dir():
        old = Path(tempfile.mkdtemp(prefix=_temp_prefix(target.name), dir=target.parent))
        os.replace(target, old / "old")
    os.replace(tmp, target)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


# ------------------------------------------------------------------------------------------ path checks
def _name_max(folder: Path) -> int:
    try:
        return int(os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError):
        return 255


def _path_max(folder: Path) -> int:
    try:
        return int(os.pathconf(folder, "PC_PATH_MAX"))
    except (OSError, ValueError):
        return 4096


def _is_link(p: Path) -> bool:
    """``p.is_symlink()``, False where the path cannot be examined (a name too long: refused later)."""
    try:
        return p.is_symlink()
    except OSError:
        return False


def check_output_path(path: str | os.PathLike, what: str = "output", *, kind: str = "file") -> Path:
    """Refuse an output path that cannot be written, before any work is done.

    Parameters
    ----------
    path : path
        Where the output will go.
    what : str
        The option that named it (``"-o"``, ``"--json"``...), for the message.
    kind : {"file", "folder"}
        A file (its folder must exist) or a folder (created with its parents if missing).

    Returns
    -------
    Path
        Where to write: ``path``, or where it points if it is a symbolic link (even a dangling one),
        so that writing by rename keeps the link.

    Raises
    ------
    InputError
        Empty, a symbolic link loop, an existing folder where a file is wanted (or a file where a folder is), a path
        through a file, a file name or path that is too long, a missing folder (for files), a
        folder that is not writable.
    """
    text = os.fspath(path)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    if not text.strip():
        raise InputError(f"{what}: the output path is empty; give a {kind} name")
    if kind == "file" and text in (".", ".."):
        raise InputError(f"{what} {text!r} is a folder; give a file name")
    if "\x00" in text:
        raise InputError(f"{what} {text!r}: a path cannot contain a NUL character")
    p = Path(text)
    if _is_link(p):  # written where the link points (as a shell redirection would), the link kept
        real = Path(os.path.realpath(p))
        if _is_link(real):
            raise InputError(f"{what} {text!r} is a symbolic link that leads to itself; choose another path")
        return check_output_path(real, what, kind=kind)
    shown = text if len(text) <= 80 else text[:38] + "..." + text[-38:]
    full = os.path.abspath(text)
    plimit = _path_max(Path("/"))
    if len(os.fsencode(full)) >= plimit:
        raise InputError(f"{what}: the path is {len(os.fsencode(full))} bytes long, more than {plimit - 1}; choose a shorter one")
    # the nearest existing ancestor: everything below it will be created
    anc = p.parent if kind == "file" else p
    missing: list[str] = []
    while True:
        try:
            st_exists = anc.exists()
        except OSError as exc:  # ENAMETOOLONG and the like
            raise InputError(f"{what} {shown!r}: {exc.strerror or exc}") from None
        if st_exists or anc == anc.parent:
            break
        missing.append(anc.name)
        anc = anc.parent
    if kind == "folder" and not missing and not anc.is_dir():
        raise InputError(f"{what} {shown!r} exists and is not a folder; choose another path")
    if not anc.is_dir():
        raise InputError(f"{what} {shown!r} goes through {str(anc)!r}, which is a file, not a folder; choose another path")
    limit = _name_max(anc)
    for part in [*missing, p.name]:
        if len(os.fsencode(part)) > limit:
            raise InputError(
                f"{what}: the name {part[:40]!r}... is {len(os.fsencode(part))} bytes long, more than the "
                f"{limit} bytes a file name may have here; choose a shorter name"
            )
    if kind == "file":
        if missing:
            raise InputError(f"{what} {shown!r}: folder {str(p.parent)!r} does not exist; create it first")
        if p.is_dir():
            raise InputError(f"{what} {shown!r} is a folder; give a file name")
        if p.exists() and not p.is_file():
            raise InputError(f"{what} {shown!r} exists and is not a regular file; choose another path")
    else:
        if p.exists() and not p.is_dir():
            raise InputError(f"{what} {shown!r} exists and is not a folder; choose another path")
    if not os.access(anc, os.W_OK | os.X_OK):
        raise InputError(f"{what} {shown!r}: the folder {str(anc)!r} is not writable; choose another path")
    try:  # what access() cannot tell (root on a read-only or pseudo file system such as /sys): try it
        fd, probe = tempfile.mkstemp(prefix=_temp_prefix("probe"), suffix=".tmp", dir=anc)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise InputError(f"{what} {shown!r}: nothing can be written in the folder {str(anc)!r} "
                         f"({exc.strerror or exc}); choose another path") from None
    return p


def _same_key(p: Path) -> str:
    return os.path.normcase(os.path.realpath(p))


class OutputSet:
    """The outputs of one command, written all-or-nothing.

    Add every output first (:meth:`add`: checked at once), do the work, stage the contents
    (:meth:`write_text`, :meth:`write_bytes`, :meth:`temp_path`), then :meth:`commit` (or leave
    the ``with`` block normally). On an exception inside the ``with`` block every temporary is
    removed and no target changes.

    Parameters
    ----------
    inputs : iterable of (path, what)
        Files the command reads: an output naming one of them is refused.

    Examples
    --------
    >>> with OutputSet() as outs:                       # doctest: +SKIP
    ...     csv_path = outs.add("pred.csv", "-o")
    ...     json_path = outs.add("pred.json", "--json")
    ...     ...                                          # the work
    ...     outs.write_text(csv_path, csv_text)
    ...     outs.write_text(json_path, json_text)
    """

    def __init__(self, inputs: Iterable[tuple[str | os.PathLike, str]] = ()) -> None:
        self._inputs = {_same_key(Path(p)): (what, Path(p)) for p, what in inputs if p is not None and os.fspath(p)}
        self._targets: dict[str, tuple[str, Path]] = {}
        self._staged: dict[str, Path] = {}
        self.committed = False

    def add(self, path: str | os.PathLike, what: str = "output", *, kind: str = "file") -> Path:
        """Check an output path (see :func:`check_output_path`) and reserve it.

        Parameters
        ----------
        path : path
        what : str
            The option that named it, for messages.
        kind : {"file", "folder"}

        Returns
        -------
        Path
            As :func:`check_output_path` returns it (a symbolic link resolved).

        Raises
        ------
        InputError
            As :func:`check_output_path`; also a path added twice or equal to an input.
        """
        p = check_output_path(path, what, kind=kind)
        key = _same_key(p)
        if key in self._targets:
            other = self._targets[key][0]
            raise InputError(f"{other} and {what} both name {str(p)!r}; give each output its own path")
        for k, (other, ip) in self._inputs.items():
            if k == key:
                raise InputError(f"{what} {str(p)!r} is also the input {other}; choose another output path")
        self._targets[key] = (what, p)
        return p

    def _slot(self, path: str | os.PathLike) -> tuple[str, Path]:
        p = Path(path)
        key = _same_key(p)
        if key not in self._targets:
            raise InputError(f"{p} was not added to this OutputSet; call OutputSet.add() with it first")
        return key, self._targets[key][1]

    def temp_path(self, path: str | os.PathLike) -> Path:
        """A temporary file beside ``path`` that becomes ``path`` on :meth:`commit` (write into it).

        Parameters
        ----------
        path : path
            An output given to :meth:`add` (the same temporary on every call).

        Returns
        -------
        Path

        Raises
        ------
        InputError
            ``path`` was not added.
        """
        key, p = self._slot(path)
        if key not in self._staged:
            self._staged[key] = _make_temp_file(p.parent if str(p.parent) else Path("."), p.name)
        return self._staged[key]

    def temp_dir(self, path: str | os.PathLike) -> Path:
        """A temporary folder beside the folder output ``path`` (added with ``kind="folder"``) that
        replaces ``path`` on :meth:`commit` (a previous folder of that name is removed then).

        Parameters
        ----------
        path : path
            A folder output given to :meth:`add`; its parent is created if missing.

        Returns
        -------
        Path
            The same temporary folder on every call for ``path``.

        Raises
        ------
        InputError
            ``path`` was not added.
        """
        key, p = self._slot(path)
        if key not in self._staged:
            parent = p.parent if str(p.parent) else Path(".")
            parent.mkdir(parents=True, exist_ok=True)
            self._staged[key] = make_temp_dir(parent, p.name)
        return self._staged[key]

    def write_bytes(self, path: str | os.PathLike, data: bytes) -> None:
        """Stage ``data`` as the content of ``path`` (an added output; see :meth:`temp_path`).

        Parameters
        ----------
        path : path
        data : bytes
        """
        tmp = self.temp_path(path)
        with open(tmp, "wb") as fh:
            fh.write(data)

    def write_text(self, path: str | os.PathLike, text: str) -> None:
        """Stage UTF-8 ``text`` as the content of ``path`` (as :meth:`write_bytes`).

        Parameters
        ----------
        path : path
        text : str
        """
        self.write_bytes(path, text.encode("utf-8"))

    def commit(self) -> list[Path]:
        """Rename every staged temporary to its target (outputs that were added but not staged are skipped).

        Returns
        -------
        list of Path
            The targets written, in staging order.
        """
        done = []
        for key, tmp in list(self._staged.items()):
            target = self._targets[key][1]
            if tmp.is_dir():
                _publish_dir(tmp, target)
                del self._staged[key]
                done.append(target)
                continue
            _publish(tmp, target)
            del self._staged[key]
            done.append(target)
        self.committed = True
        return done

    def discard(self) -> None:
        """Remove every staged temporary; no target is touched."""
        for tmp in self._staged.values():
            try:
                if tmp.is_dir():
                    shutil.rmtree(tmp, ignore_errors=True)
                else:
                    tmp.unlink()
            except OSError:
                pass
        self._staged.clear()

    def __enter__(self) -> "OutputSet":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None and not self.committed:
            try:
                self.commit()
            finally:
                self.discard()
        else:
            self.discard()


# ------------------------------------------------------------------------------------------ single files
def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file in the same folder and a rename.

    The parent folder must exist. On any error the target is left untouched. A symbolic link at
    ``path`` is kept: the file it points to is written.

    Parameters
    ----------
    path : path
    data : bytes

    Returns
    -------
    Path
        Where the data went (the link's target for a symbolic link).

    Raises
    ------
    FileNotFoundError
        The parent folder does not exist.
    OSError
        The write or the rename failed.
    """
    target = Path(path)
    if _is_link(target):  # the link is kept; its target is written
        target = Path(os.path.realpath(target))
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.is_dir():
        raise FileNotFoundError(f"folder {parent} does not exist; create it first")
    tmp = _make_temp_file(parent, target.name)
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
        _publish(tmp, target)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return target


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """UTF-8 text version of :func:`atomic_write_bytes`.

    Parameters
    ----------
    path : path
    text : str

    Returns
    -------
    Path
        Where the text went.
    """
    return atomic_write_bytes(path, text.encode("utf-8"))


# ------------------------------------------------------------------------------------------ signals
def _terminated(signum, frame) -> None:  # pragma: no cover - exercised in a subprocess
    signal.signal(signum, signal.SIG_DFL)  # a second SIGTERM kills at once
    raise SystemExit(128 + signum)


def install_termination_handler() -> None:
    """Make ``SIGTERM`` raise ``SystemExit(143)`` so that ``finally`` blocks and :class:`OutputSet`
    remove their temporaries (the default action would kill the process on the spot).

    Only in the main thread (signal handlers cannot be set elsewhere); a no-op otherwise.
    """
    try:
        signal.signal(signal.SIGTERM, _terminated)
    except ValueError:
        pass

