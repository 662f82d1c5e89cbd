"""What must hold before a sweep starts: no other sweep writes into its directory
(:func:`lock_output`), and the Ray cluster that ``--address`` names answers
(:func:`split_address`, :func:`check_ray_address`). Each failure is a
:class:`SweepError` that says what to do."""
from __future__ import annotations

import logging
import os
import re
import socket
import sys
import time
from typing import Optional, Tuple

__all__ = ["CONNECT_TIMEOUT", "LOCK_FILE", "RAY_CLIENT_PORT", "SweepError", "split_address",
           "check_ray_address", "lock_output"]

logger = logging.getLogger(__name__)

#: seconds a Ray cluster named by --address has to accept a connection
CONNECT_TIMEOUT = 5.0

#: the file in the sweep directory that a running sweep holds locked
LOCK_FILE = "sweep.lock"

#: Ray's default ports: the head's GCS (HOST:PORT addresses) and the Ray client server
RAY_CLIENT_PORT = 10001

_HOST_PORT = re.compile(r"^(?:\[(?P<ip6>[0-9A-Fa-f:.]+)\]|(?P<host>[A-Za-z0-9_.-]+))"
                        r"(?::(?P<port>\d+))?$")


class SweepError(Exception):
    """A sweep that cannot start: its directory is in use, its Ray cluster does not answer."""


def split_address(address: str) -> Optional[Tuple[str, int]]:
    """``(host, port)`` that ``--address`` connects to: ``HOST:PORT`` (a head's GCS port)
    or ``ray://HOST[:PORT]`` (the Ray client, port 10001 by default); None for ``auto``,
    ``local`` and other ``SCHEME://`` addresses (left to Ray). ValueError for anything
    else."""
    if not isinstance(address, str) or not address.strip():
        raise ValueError(f"--address must be auto, HOST:PORT or ray://HOST[:PORT], "
                         f"got {address!r}")
    if address in ("auto", "local"):
        return None
    scheme, sep, rest = address.partition("://")
    if sep and scheme != "ray":
        return None  # a Ray client plug-in's scheme: Ray checks it
    m = _HOST_PORT.match(rest if sep else address)
    if m is None or (not sep and m.group("port") is None):
        raise ValueError(f"--address must be auto, HOST:PORT or ray://HOST[:PORT], "
                         f"got {address!r}")
    port = int(m.group("port")) if m.group("port") is not None else RAY_CLIENT_PORT
    if not 0 < port < 65536:
        raise ValueError(f"--address {address}: port {port} is not in 1-65535")
    return m.group("ip6") or m.group("host"), port


def _ray_address_file() -> str:
    """The file in which ``ray start --head`` records its address (Ray's temporary
    folder: ``$RAY_TMPDIR/ray``, on Linux else ``$TMPDIR/ray``, else ``/tmp/ray``)."""
    try:
        from ray._common.utils import get_ray_address_file  # Ray's own rule

        return get_ray_address_file(None)
    except Exception:  # an older or newer Ray: the same rule, by hand
        base = os.environ.get("RAY_TMPDIR") or (
            os.environ.get("TMPDIR") if sys.platform.startswith("linux") else None) or "/tmp"
        return os.path.join(base, "ray", "ray_current_cluster")


def _auto_address() -> Tuple[Optional[str], str]:
    """What ``--address auto`` connects to first, as Ray finds it: ``RAY_ADDRESS``, else
    the address recorded by the last ``ray start --head`` here; ``(None, "")`` when
    neither is set (Ray then looks for any Ray process on the machine)."""
    env = os.environ.get("RAY_ADDRESS", "").strip()
    if env:
        return env, "the RAY_ADDRESS environment variable"
    path = _ray_address_file()
    try:
        with open(path, encoding="utf-8") as fh:
            recorded = fh.read().strip()
    except OSError:
        return None, ""
    return (recorded, path) if recorded else (None, "")


def check_ray_address(address: Optional[str], timeout: float = CONNECT_TIMEOUT) -> None:
    """Raise :class:`SweepError` unless the Ray cluster ``address`` names accepts a TCP
    connection within ``timeout`` seconds (``ray.init`` would wait for minutes on a
    cluster that is gone). ``None``/``local`` (a Ray of the sweep's own) pass; ``auto``
    checks the address Ray would take (``RAY_ADDRESS`` or the one recorded by ``ray
    start``), so a stopped head's stale record fails here."""
    if address in (None, "local"):
        return
    target, source = (address, "") if address != "auto" else _auto_address()
    if target is None:
        return  # ray.init(address="auto") looks for a running Ray itself
    try:
        where = split_address(target)
    except ValueError as err:
        raise SweepError(f"--address {address}: {target!r} from {source} is no Ray "
                         f"address ({err})") from None
    if where is None:
        return
    host, port = where
    try:
        with socket.create_connection((host, port), timeout=timeout):
            pass
    except OSError as err:
        reason = f"no answer within {timeout:g} s" if isinstance(err, socket.timeout) \
            else (err.strerror or str(err))
        named = f"{target} (recorded in {source})" if source else target
        advice = ("that cluster has stopped: start one with `ray start --head`, or "
                  f"remove {source}" if source.endswith("ray_current_cluster") else
                  "is the cluster running and its port open from here?")
        raise SweepError(f"--address {address}: no Ray cluster answers at {named}: "
                         f"{reason}; {advice}; or leave out --address for a Ray of the "
                         f"sweep's own") from None


def lock_output(directory: str):
    """Hold an exclusive lock on ``directory``/``sweep.lock`` (created with the directory)
    and return its open file: the lock lasts until that file is closed or the process
    ends, however it ends. :class:`SweepError` naming the holder when another process
    holds it."""
    os.makedirs(directory, exist_ok=True)
    path = os.path.join(directory, LOCK_FILE)
    fh = open(path, "a+", encoding="utf-8")
    try:
        import fcntl
    except ImportError:  # no flock (Windows): no protection, say so
        logger.warning("cannot lock %s on this system: do not start a second sweep into "
                       "it", directory)
        return fh
    try:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        fh.seek(0)
        holder = fh.read().strip() or "a process"
        fh.close()
        raise SweepError(f"another sweep ({holder}) is running in {directory}: wait for "
                         f"it to end, or choose another --output") from None
    fh.seek(0)
    fh.truncate()
    fh.write(f"pid {os.getpid()} on {socket.gethostname()} since "
             f"{time.strftime('%Y-%m-%dT%H:%M:%S')}\n")
    fh.flush()
    return fh

