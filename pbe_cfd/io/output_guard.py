"""Claims on an output directory DIR, and the leftovers of runs that were killed.

* One pbe-cfd process at a time writes DIR: it holds an exclusive ``flock`` on the lock file
  ``.DIR.pbe-cfd-lock`` beside DIR from the check before the computation to the end of the
  write (the kernel releases it when the process dies, even by kill -9). A second run into the
  same DIR is refused at once (``Busy``). A lock file that still names a pid when its lock is
  free was left by a run killed before it released it (kill -9, a crash): it is taken over
  and ``recover`` says so in one line.
* A run fills ``.DIR.partial-*`` (marked by ``manifest.PARTIAL_MARKER``, later by its
  manifest) and swaps it with DIR in one rename; a run killed before the swap leaves that
  directory behind, one killed after it leaves the earlier output there, and (on a file system
  without an atomic exchange) one killed between the two renames leaves ``.DIR.old-*`` and no
  DIR. ``recover`` finds them when the next run claims DIR: it restores a missing DIR from its
  ``.old-*`` and removes the others, file by file, only what pbe-cfd wrote.
"""
from __future__ import annotations

import ctypes
import errno
import fcntl
import os
import shutil
from pathlib import Path

from . import manifest as mf

_held: dict[Path, int] = {}
_stale: dict[Path, str] = {}


class Busy(Exception):
    """Another process holds the lock of the output directory."""


def lock_path(target: Path) -> Path:
    """The lock file of output directory ``target``: ``.NAME.pbe-cfd-lock`` beside it."""
    return target.parent / f".{target.name}.pbe-cfd-lock"


def claim(target: Path):
    """Take the exclusive lock of ``target`` (a resolved path whose parent exists) for this
    process; a no-op when already held. Raises Busy (naming the holder's pid) or OSError (the
    parent is not writable)."""
    if target in _held:
        return
    path = lock_path(target)
    mask = os.umask(0o022)
    os.umask(mask)
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666 & ~mask)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            holder = os.read(fd, 32).decode(errors="replace").strip()
            os.close(fd)
            if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN):
                raise Busy(holder or "?") from None
            raise
        try:                  # the previous holder may have unlinked the file we opened
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    previous = os.read(fd, 32).decode(errors="replace").strip()
    if previous.isdigit() and int(previous) != os.getpid():
        _stale[target] = previous
    os.ftruncate(fd, 0)
    os.lseek(fd, 0, os.SEEK_SET)
    os.write(fd, f"{os.getpid()}\n".encode())
    _held[target] = fd


def _stale_state(pid: str) -> str:
    """What became of ``pid``, the holder named by a lock file whose lock was free."""
    try:
        os.kill(int(pid), 0)
        return f"pid {pid} is now another process"
    except ProcessLookupError:
        return f"pid {pid} no longer runs"
    except (OSError, OverflowError):
        return f"pid {pid} does not hold it"


def release(target: Path):
    """Give up the lock of ``target`` (and remove the lock file) if this process holds it."""
    fd = _held.pop(target, None)
    _stale.pop(target, None)
    if fd is None:
        return
    try:
        os.unlink(lock_path(target))
    except OSError:
        pass
    os.close(fd)


def release_all():
    """Give up every lock this process holds."""
    for target in list(_held):
        release(target)


def held() -> list[Path]:
    """The output directories this process has claimed."""
    return list(_held)


def _is_leftover(path: Path, target: Path) -> bool:
    name = path.name
    if not (name.startswith(f".{target.name}.partial-") or name.startswith(f".{target.name}.old-")):
        return False
    if path.is_symlink() or not path.is_dir():
        return False
    return (path / mf.PARTIAL_MARKER).is_file() or (path / mf.MANIFEST).is_file()


def leftovers(target: Path) -> list[Path]:
    """The leftover directories of interrupted runs into ``target``, beside it."""
    try:
        siblings = list(target.parent.iterdir())
    except OSError:
        return []
    return sorted(p for p in siblings if _is_leftover(p, target))


def remove_leftover(path: Path, target: Path) -> list[str]:
    """Remove, file by file, what pbe-cfd wrote into the leftover directory ``path``: all of a
    partial directory still marked as being filled; else a file listed unchanged in its
    manifest, a hard link of which another name survives, or a copy of the file at the same
    place in ``target``. Returns the files kept (then the directory stays)."""
    marked = (path / mf.PARTIAL_MARKER).is_file()
    own = mf.read_manifest(path)
    files = own["files"] if own else {}
    kept = []
    for rel in mf.files_under(path):
        p = path / rel
        try:
            st = p.lstat()
        except OSError:
            continue
        ours = marked or st.st_nlink > 1 or (rel in files and mf.unchanged(p, files[rel]))
        if not ours:
            try:
                twin = (target / rel).lstat()
                ours = (twin.st_size, twin.st_mtime_ns) == (st.st_size, st.st_mtime_ns)
            except OSError:
                ours = False
        if ours:
            p.unlink()
        else:
            kept.append(rel)
    if kept:
        return kept
    for name in (mf.MANIFEST, mf.PARTIAL_MARKER, f".{mf.MANIFEST}.tmp"):
        (path / name).unlink(missing_ok=True)
    for dirpath, _, _ in sorted(os.walk(path), key=lambda w: -len(w[0])):
        try:
            os.rmdir(dirpath)
        except OSError:
            pass
    return []


def recover(target: Path) -> list[str]:
    """Deal with the leftovers of interrupted runs into ``target`` (call with its lock held):
    a missing ``target`` is restored from its ``.old-*``, the rest removed. Returns one
    sentence per leftover for the user; a lock taken over from a killed run (``claim``) is
    said in the first of them, or in a sentence of its own."""
    notes = []
    pid = _stale.pop(target, None)
    for path in leftovers(target):
        if not os.path.lexists(target) and path.name.startswith(f".{target.name}.old-"):
            os.rename(path, target)
            notes.append(f"restored {target} from {path.name} (a run was killed while "
                         "replacing it)")
            continue
        kept = remove_leftover(path, target)
        if kept:
            notes.append(f"kept {path} left by an interrupted run: it holds "
                         f"{', '.join(kept[:3])}{' ...' if len(kept) > 3 else ''}, which "
                         "pbe-cfd did not write")
        else:
            notes.append(f"removed {path.name} left by an interrupted run")
    if pid is not None:
        lock = lock_path(target).name
        if notes:             # the killed run's leftovers and its lock: one line
            notes[0] += (f" (killed before it finished; took over its lock {lock}: "
                         f"{_stale_state(pid)})")
        else:
            notes.append(f"took over the lock {lock} left by a run that was killed before it "
                         f"finished ({_stale_state(pid)})")
    return notes


# ---------------------------------------------------------------------------- the swap
def make_dirs(src_root: Path, dst_root: Path, rel: str):
    """Create ``dst_root/rel`` and its missing parents with the modes of ``src_root``'s."""
    parts = Path(rel).parts
    for k in range(1, len(parts) + 1):
        sub = Path(*parts[:k])
        if not (dst_root / sub).is_dir():
            (dst_root / sub).mkdir()
            shutil.copymode(src_root / sub, dst_root / sub)


def carry(src_root: Path, dst_root: Path, rel: str):
    """Keep the file (or symlink) ``rel`` of ``src_root`` in ``dst_root``: a hard link (the
    same file, its content and times), a copy where links are not possible."""
    src, dst = src_root / rel, dst_root / rel
    if Path(rel).parent != Path("."):
        make_dirs(src_root, dst_root, Path(rel).parent.as_posix())
    try:
        os.link(src, dst, follow_symlinks=False)
    except OSError as exc:
        if exc.errno not in (errno.EXDEV, errno.EPERM, errno.EMLINK, errno.ENOTSUP):
            raise
        if src.is_symlink():
            os.symlink(os.readlink(src), dst)
        else:
            shutil.copy2(src, dst)


_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _renameat2_exchange(a, b):
    """Exchange the paths ``a`` and ``b`` in one atomic rename (Linux renameat2)."""
    libc = ctypes.CDLL(None, use_errno=True)
    fn = getattr(libc, "renameat2", None)
    if fn is None:
        raise OSError(errno.ENOSYS, "renameat2 not available")
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) != 0:
        code = ctypes.get_errno()
        raise OSError(code, os.strerror(code), str(a))


def swap(new_dir: Path, target: Path) -> Path:
    """Put ``new_dir`` in the place of ``target``; returns where the earlier ``target`` went.
    One atomic exchange where the file system has it, else two renames (a crash between them
    leaves ``.DIR.old-*``, which the next run restores)."""
    try:
        _renameat2_exchange(new_dir, target)
        return new_dir
    except OSError as exc:
        if exc.errno not in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP, errno.EPERM):
            raise
    old = new_dir.with_name(new_dir.name.replace(".partial-", ".old-", 1))
    os.rename(target, old)
    os.rename(new_dir, target)
    return old
