"""The one door to a Ray cluster (``--ray [ADDRESS]`` of ``alphatank train`` and
``alphatank experiments``).

Nothing here imports Ray until :func:`connect` is called, and nothing in AlphaTank calls
it unless ``--ray`` was given: without it Ray is never imported. Ray
is the ``ray`` install extra; :func:`connect` says how to install it when it is missing.

``connect(None)`` starts a private local instance (``ray.init(address="local")``: never
the cluster some earlier ``ray start`` left on this machine) with every core of the
machine; ``connect("HOST:PORT")`` joins a running cluster (``ray start --head`` on one
host, ``ray start --address HOST:PORT`` on the others; docs/distributed.md).
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import threading
import time
from dataclasses import dataclass
from typing import Any

from alphatank.errors import InputError
from alphatank.extras import require


class ClusterError(InputError):
    """The Ray cluster at an address cannot be reached (one line, naming it)."""


@dataclass(frozen=True)
class Connection:
    """A live connection: where, how many CPUs the cluster has, how long start-up took,
    whether it is a local instance started here, and whether :func:`connect` made it
    (then :meth:`close` ends it; a caller's own ``ray.init`` is left alone)."""

    address: str
    cpus: float
    nodes: int
    seconds: float
    local: bool
    owned: bool
    handlers: tuple[Any, ...] = ()  # SIGINT, SIGTERM handlers from before ray.init

    def describe(self) -> str:
        how = ("started a local Ray instance" if self.local else
               f"joined the Ray cluster at {self.address}")
        return f"ray: {how} ({self.nodes} node(s), {self.cpus:g} CPUs) in {self.seconds:.1f} s"

    def close(self) -> None:
        """Leave the cluster (a local instance started here stops) if connect() joined."""
        import ray

        if self.owned and ray.is_initialized():
            ray.shutdown()
        if self.handlers and threading.current_thread() is threading.main_thread():
            for sig, handler in zip(SIGNALS, self.handlers, strict=True):
                if handler is not None:  # None: not set from Python
                    signal.signal(sig, handler)  # ray.init replaced them


PROBE_TIMEOUT_S = 5.0
# the client preface of HTTP/2 (gRPC) and an empty SETTINGS frame
H2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])
ENV_RUNNER_TIMEOUT_S = 60.0  # an env runner silent this long on one call is hung: restart it
SIGNALS = (signal.SIGINT, signal.SIGTERM)


def _reachable(address: str) -> None:
    """Fail fast (ClusterError) when ``HOST:PORT`` is malformed, nothing listens there, or
    what listens is not a Ray head's GCS port (a gRPC server: it answers an HTTP/2
    preface with a SETTINGS frame; the dashboard's 8265 does not): Ray itself keeps
    retrying for minutes. Forms without a port (``auto``) and ``ray://...`` go to Ray as
    they are; so does any address when ``RAY_USE_TLS`` is on (the port speaks TLS)."""
    if ":" not in address or "://" in address:
        return
    host, _, port = address.rpartition(":")
    host = host.strip("[]")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ClusterError(f"--ray {address}: not HOST:PORT (a head node's GCS port, "
                           f"e.g. 10.0.0.5:6379); --ray without ADDRESS starts a local "
                           f"instance")
    try:
        with socket.create_connection((host, int(port)), PROBE_TIMEOUT_S) as sock:
            if os.environ.get("RAY_USE_TLS", "0").lower() in ("1", "true"):
                return
            sock.settimeout(PROBE_TIMEOUT_S)
            sock.sendall(H2_PREFACE)
            head = b""
            with contextlib.suppress(OSError):  # a timeout or a reset: not gRPC either
                while len(head) < 9 and (chunk := sock.recv(9 - len(head))):
                    head += chunk
    except OSError as exc:
        raise ClusterError(f"--ray {address}: nothing answers there ({exc.strerror or exc}); "
                           f"start a head node with `ray start --head --port {port}` "
                           f"(docs/distributed.md)") from None
    if len(head) < 9 or head[3] != 0x04:  # the server's first frame is its SETTINGS
        got = f": it answered {head[:9]!r}" if head else ""
        raise ClusterError(f"--ray {address}: that port is not a Ray cluster's (it does not "
                           f"speak gRPC{got}); give the GCS port that `ray start --head` "
                           f"printed (6379 unless --port said otherwise; the dashboard's "
                           f"8265 is not it)")


def ray_module(feature: str) -> Any:
    """``import ray``, or :class:`~alphatank.extras.MissingExtraError` naming ``feature``
    and the pip line that installs the extra."""
    require("ray", feature)
    import ray

    return ray


def connect(address: str | None = None, *, num_cpus: int | None = None,
            feature: str = "--ray") -> Connection:
    """Join the cluster at ``address`` (``HOST:PORT``), or start a local instance with
    ``num_cpus`` (default: every core) when ``address`` is None or empty. A process
    already connected (a caller's own ``ray.init``) keeps its connection."""
    ray = ray_module(feature)
    t0 = time.perf_counter()
    owned = local = False
    handlers: tuple[Any, ...] = ()
    if not ray.is_initialized():
        owned = True
        handlers = tuple(signal.getsignal(s) for s in SIGNALS)
        opts: dict[str, Any] = {"logging_level": "WARNING", "log_to_driver": True}
        if address:
            _reachable(address)
            try:
                ray.init(address=address, **opts)
            except (ConnectionError, ValueError, RuntimeError) as exc:
                first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
                raise ClusterError(f"--ray {address}: cannot join the Ray cluster there "
                                   f"({type(exc).__name__}: {first}); start one with "
                                   f"`ray start --head` (docs/distributed.md)") from None
        else:
            # Ray runs its workers at nice 15 (below the raylet); env runners are the hot
            # path, so a local instance runs them at the driver's priority (as the worker
            # processes of --workers); a cluster's nodes set it at `ray start`
            os.environ.setdefault("RAY_worker_niceness", "0")
            ray.init(address="local", num_cpus=num_cpus or os.cpu_count() or 1,
                     include_dashboard=False, **opts)
            local = True
    resources = ray.cluster_resources()
    nodes = sum(1 for n in ray.nodes() if n.get("Alive"))
    ctx = ray.get_runtime_context()
    return Connection(address=str(getattr(ctx, "gcs_address", address or "local")),
                      cpus=float(resources.get("CPU", 0.0)), nodes=nodes,
                      seconds=time.perf_counter() - t0, local=local, owned=owned,
                      handlers=handlers)
