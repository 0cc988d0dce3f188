"""Atomic writes: a file appears complete or not at all, never half-written.

:func:`atomic_write` writes to a temporary file next to the target and renames it over the
target; :func:`remove_stale_partials` removes the temporary files a killed process left;
:func:`check_distinct` refuses an output that is the input file.
"""

import os
import tempfile

from .data import MeshFileError

__all__ = ["atomic_write", "check_distinct", "remove_stale_partials", "host_tag",
           "PARTIAL_SUFFIX"]

# The process's umask, read once (reading it means setting it, which is not thread-safe):
# finished files get the usual permissions 0666 & ~umask instead of mkstemp's 0600.
_UMASK = os.umask(0)
os.umask(_UMASK)

# Suffix of the temporary files of :func:`atomic_write`, named
# ``.<name>.<host>.<pid>.<random>.part`` so that a later write can tell a stale one (its process
# on this host is gone) from one a concurrent run is still writing.
PARTIAL_SUFFIX = ".part"
_HOST = None


def check_distinct(input_path, output_path):
    """Raise MeshFileError if ``output_path`` names the same file as ``input_path``, or a
    directory (checked before any work: the rename at the end would fail)."""
    if os.path.isdir(output_path):
        raise MeshFileError(f"{output_path}: is a directory; give the output file's name")
    same = os.path.realpath(input_path) == os.path.realpath(output_path)
    if not same and os.path.exists(output_path) and os.path.exists(input_path):
        same = os.path.samefile(input_path, output_path)
    if same:
        raise MeshFileError(f"{output_path}: refusing to overwrite the input file")


def host_tag():
    """This host's name as one dot-free token of a temporary file name (str)."""
    global _HOST
    if _HOST is None:
        import re
        import socket

        _HOST = re.sub(r"[^A-Za-z0-9_-]", "-", socket.gethostname()) or "localhost"
    return _HOST


def _pid_alive(pid):
    """Whether a process ``pid`` exists on this host (signal 0: nothing is sent)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: alive, another user's
        return True
    return True


def _stale_pid(entry, names, host):
    """The pid that wrote the temporary file ``entry`` (a basename) for one of the targets
    ``names`` on ``host``, or None when ``entry`` is no such file."""
    if not (entry.startswith(".") and entry.endswith(PARTIAL_SUFFIX)):
        return None
    parts = entry[1:-len(PARTIAL_SUFFIX)].rsplit(".", 3)
    if len(parts) != 4 or parts[0] not in names or parts[1] != host or not parts[2].isdigit():
        return None
    return int(parts[2])


def remove_stale_partials(directory, names):
    """Remove the temporary files of :func:`atomic_write` for the targets ``names`` (basenames)
    in ``directory`` whose writing process, on this host, is no longer alive; returns the paths
    removed. A live process's file (another run writing the same target) is never touched;
    files of other hosts (a shared folder) and of other naming schemes are left alone."""
    if os.name != "posix":  # os.kill(pid, 0) is no liveness test on Windows
        return []
    names = set(names)
    host = host_tag()
    removed = []
    try:
        entries = os.listdir(directory)
    except OSError:
        return []
    for entry in entries:
        pid = _stale_pid(entry, names, host)
        if pid is None or pid == os.getpid() or _pid_alive(pid):
            continue
        path = os.path.join(directory, entry)
        try:
            os.remove(path)
            removed.append(path)
        except OSError:  # removed by a concurrent run, or not ours to remove
            pass
    return removed


def atomic_write(path, write_fn):
    """Call ``write_fn(tmp_path)`` on a temporary file next to ``path``, then rename it.

    Readers never see a partial file: on success the temporary file replaces ``path`` in one
    ``os.replace``; on any failure it is removed and the exception propagates. The folder of
    ``path`` is created if missing. Safe to call from several threads and processes at once.

    The temporary file is ``.<name>.<host>.<pid>.<random>.part``; one left by a killed process
    (nothing can remove it then) is removed by the next write of the same ``path`` from this
    host, once no process of that pid is alive.
    """
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    name = os.path.basename(path)
    remove_stale_partials(directory, [name])
    fd, tmp = tempfile.mkstemp(dir=directory, prefix=f".{name}.{host_tag()}.{os.getpid()}.",
                               suffix=PARTIAL_SUFFIX)
    os.close(fd)
    try:
        write_fn(tmp)
        os.chmod(tmp, 0o666 & ~_UMASK)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise
