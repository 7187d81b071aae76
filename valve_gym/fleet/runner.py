"""Run a fleet of loops on Ray: one task per loop, results streamed to disk, resumable.

:func:`run_fleet` lists the loops of a folder or a wide export, skips those
whose stored result has the same key (content of the data + tag + settings,
:func:`~valve_gym.fleet.result.loop_key`), and runs the others as Ray tasks
(:func:`~valve_gym.fleet.analyse.analyse_loop`), at most a few per CPU in
flight, so only the loops being worked on are in memory.  Each result is
written as ``OUT/loops/<loop>.json`` the moment it arrives (``ray.wait``;
atomic), the table ``loops.parquet``/``loops.csv`` every 30 s and at the end,
then the worklist.  Ctrl-C (or SIGTERM) cancels the loops in flight and keeps
every finished one; running again continues.  A signal is only noted while Ray
starts and while the table and the worklist are written (:class:`_Stop`): the run
stops once Ray is up, the table and the worklist are written whole, and Ray is
always shut down before the call returns, after them (a Ray without the switch of
:func:`_signals_left_to_python` leaves SIGTERM to its default action as it shuts down).

Ray runs in this process by default (``ray.init(address='local', num_cpus=jobs)``, no
dashboard, nothing to start, whatever cluster runs nearby); ``address`` joins an existing
cluster (its nodes need valve_gym's dependencies; valve_gym itself is sent along where they lack it,
see :func:`_probe_cluster`; a cluster with token authentication
needs ``RAY_AUTH_MODE=token`` and its token in this process's environment).  On a cluster the
data files travel with the tasks (each file's bytes put in Ray's object store once, while
its loops are in flight): a node need not see this machine's files.  A Ray session
already started by the caller is used as it is and left running.
"""
from __future__ import annotations

import contextlib
import logging
import os
import signal
import sys
import tempfile
import time
from collections.abc import Callable, Generator, Iterator
from dataclasses import fields, replace
from typing import Any, NamedTuple

from .analyse import analyse_loop, failed_result
from .plantwide import apply_shared_periods
from .progress import Progress
from .result import FleetSettings, LoopResult, loop_key
from .sources import FLEET_OUTPUT_FILES, LoopSource, discover_loops, fleet_outputs
from .table import read_result, write_result, write_table

__all__ = ["FleetRun", "run_fleet", "plan_fleet", "check_out_dir", "local_results", "ENGINES"]

_TABLE_EVERY_S = 30.0


class FleetRun(NamedTuple):
    """Summary of one :func:`run_fleet` call.

    Attributes
    ----------
    n_loops : int, loops found
    done : int, loops analysed in this run
    resumed : int, loops whose stored result was reused
    failed : int, loops with status other than ``'ok'`` (this run and resumed)
    interrupted : bool, a Ctrl-C / SIGTERM came during the run (loops may be left; the table and the
        worklist are written whole)
    remaining : int, loops left for a later run (interrupted or ``max_loops``)
    seconds : float, wall time [s] of this call
    results : list of LoopResult, of every loop with a result, in discovery order
    paths : dict of str to str, ``table``, ``csv``, ``worklist_md``, ``worklist_html``
    """

    n_loops: int
    done: int
    resumed: int
    failed: int
    interrupted: bool
    remaining: int
    seconds: float
    results: list
    paths: dict


def plan_fleet(sources: list[LoopSource], out_dir: str, settings: FleetSettings):
    """Split ``sources`` into stored results to reuse and loops to run.

    Returns
    -------
    keys : dict loop name -> resume key
    stored : dict loop name -> LoopResult, reusable results (same key; status not ``'error'``)
    todo : list of LoopSource, in discovery order
    """
    keys, stored, todo = {}, {}, []
    for s in sources:
        k = loop_key(s.fingerprint, s.kind, s.tag, settings)
        keys[s.name] = k
        old = read_result(os.path.join(out_dir, "loops", s.name + ".json"))
        if old is not None and old.key == k and old.status != "error":
            stored[s.name] = old
        else:
            todo.append(s)
    return keys, stored, todo


def _remote(settings: FleetSettings):
    import ray

    @ray.remote(num_cpus=1, max_retries=1)
    def task(src: LoopSource, key: str, data: bytes | None) -> LoopResult:
        try:
            from ..diagnosis.model import set_kernel_threads
            set_kernel_threads(1)          # one CPU per task: no threads on top
        except (ImportError, ValueError):
            pass
        if data is None:
            return analyse_loop(src, settings, key)
        return analyse_shipped(src, data, settings, key)

    return task


def analyse_shipped(src: LoopSource, data: bytes, settings: FleetSettings, key: str = "") -> LoopResult:
    """:func:`~valve_gym.fleet.analyse.analyse_loop` of a loop whose file's bytes came with the task.

    The bytes are written to a private temporary folder under the file's own name (its
    extension decides how it is read) and removed afterwards; the result names the file
    by its path on the machine that sent it, as a run without a cluster would.
    """
    with tempfile.TemporaryDirectory(prefix="valve_gym-loop-") as d:
        local = os.path.join(d, os.path.basename(src.path) or "loop.csv")
        with open(local, "wb") as f:
            f.write(data)
        res = analyse_loop(replace(src, path=local), settings, key)
    return _renamed(res, local, src.path)


def _renamed(res: LoopResult, local: str, path: str) -> LoopResult:
    """``res`` with the temporary path ``local`` replaced by ``path`` in its text fields."""
    kw: dict = {}
    for f in fields(res):
        v = getattr(res, f.name)
        if isinstance(v, str) and local in v:
            kw[f.name] = v.replace(local, path)
        elif isinstance(v, tuple) and any(isinstance(x, str) and local in x for x in v):
            kw[f.name] = tuple(x.replace(local, path) if isinstance(x, str) else x for x in v)
    return replace(res, **kw) if kw else res


class _Shipper:
    """The file bytes of the loops in flight, one object per file in Ray's store (cluster runs).

    ``ref(src)`` puts the file's bytes once and counts the loop; ``done(src)`` drops the object
    when the file's last loop in flight is back.  Off (``None`` for every loop) in this
    process's own Ray, whose workers read the files themselves.
    """

    def __init__(self, on: bool):
        self.on = on
        self.refs: dict[str, tuple[Any, int]] = {}

    def ref(self, src: LoopSource) -> Any:
        if not self.on or src.kind == "bad":
            return None
        import ray

        obj, n = self.refs.get(src.path, (None, 0))
        if obj is None:
            try:
                with open(src.path, "rb") as f:
                    obj = ray.put(f.read())
            except OSError:
                return None                  # the worker reports the file as it finds it
        self.refs[src.path] = (obj, n + 1)
        return obj

    def done(self, src: LoopSource) -> None:
        obj, n = self.refs.get(src.path, (None, 0))
        if obj is None:
            return
        if n <= 1:
            del self.refs[src.path]
        else:
            self.refs[src.path] = (obj, n - 1)


#: Seconds a cluster's head node has to answer before ``address`` is reported unreachable.
CONNECT_TIMEOUT = 5.0


#: Port of a head node's Ray Client server (``ray://HOST`` without a port).
RAY_CLIENT_PORT = 10001


def check_address(address: str | None) -> None:
    """Refuse, at once, a Ray address that is neither ``auto`` nor a reachable ``[ray://]host:port``.

    Ray itself retries an address that does not answer for minutes (a ``ray://`` Ray Client
    address for about 30 s, then blames the connection).  ``ray://HOST`` without a port is checked
    at the Ray Client's default port :data:`RAY_CLIENT_PORT`.  Raises ValueError naming the
    address and what to do.
    """
    if not address or address == "auto":
        return
    client = address.startswith("ray://")
    rest = address[len("ray://"):] if client else address
    host, sep, port = rest.rpartition(":")
    if client and not sep:
        host, port = rest, str(RAY_CLIENT_PORT)
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"address {address!r}: give 'auto', HOST:PORT of a running Ray cluster's head "
                         f"(e.g. 10.0.0.5:6379) or ray://HOST:PORT of its Ray Client server (e.g. "
                         f"ray://10.0.0.5:{RAY_CLIENT_PORT})")
    import socket

    try:
        socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT).close()
    except OSError as e:
        what = "no Ray Client server answers there" if client else "no Ray cluster answers there"
        raise ValueError(f"address {address!r}: {what} ({e}); start one with 'ray start --head' (its Ray "
                         f"Client server listens on port {RAY_CLIENT_PORT}) or leave the address out to run "
                         f"Ray in this process") from None


def _start_ray(jobs: int, address: str | None, say: Callable[[str], None] | None = None,
               stopped: Callable[[], bool] | None = None) -> bool:
    """Start Ray unless a session exists; True if this call started it.

    Without ``address`` a new Ray instance starts in this process (``address='local'``), even where
    a cluster runs on this machine or ``RAY_ADDRESS`` names one: plain ``ray.init()`` would join it
    and refuse ``num_cpus``.  With ``address`` a head node that does not answer, or refuses this
    process (token authentication), is a ValueError that says what to do; then the cluster is
    probed (:func:`_probe_cluster`; ``stopped`` ends its wait).  A start that is cut short
    (:func:`_init`) shuts down what it had started and raises KeyboardInterrupt.
    """
    import ray

    if ray.is_initialized():
        return False
    kw = {"include_dashboard": False, "configure_logging": True, "logging_level": logging.ERROR,
          "log_to_driver": False}
    if not address:
        with _signals_left_to_python():
            _init(address="local", num_cpus=int(jobs), **kw)
        return True
    check_address(address)
    try:
        with _signals_left_to_python():
            _init(address=address, **kw)
    except ConnectionError as e:
        raise ValueError(
            f"could not join the Ray cluster at {address}: {e}. A cluster started with token "
            f"authentication (what `ray start` does by default since Ray 2.59) admits only clients that "
            f"run with RAY_AUTH_MODE=token and its token (~/.ray/auth_token on this machine, or "
            f"RAY_AUTH_TOKEN; `ray get-auth-token` on the head node prints it)") from None
    try:
        sent = _probe_cluster(address, kw, stopped)
    except BaseException:
        ray.shutdown()
        raise
    if sent and say is not None:
        say(f"note: valve_gym is not installed on the nodes of {address}: sent along with this run (each "
            f"node compiles its kernels first, about a minute)")
    return True


@contextlib.contextmanager
def _signals_left_to_python() -> Iterator[None]:
    """Within: a Ray driver started here installs no crash handler of its own (the workers keep theirs).

    Ray's core worker installs a C++ failure-signal handler (abseil's) for SIGTERM among others, in front of
    Python's: a SIGTERM in the last moments of Ray's start met it first (a stack printed; the exit status
    could be 134), and as Ray shuts down it puts the default action back (a SIGTERM in that second ended the
    command with 143, the handler of :class:`_Stop` never told).  Ray's own switch for this,
    ``RAY_DISABLE_FAILURE_SIGNAL_HANDLER``, is read as a constant when the core worker starts; it is set
    for this process only while Ray starts, and put back after.
    """
    try:
        from ray._private import ray_constants
    except ImportError:                          # another Ray layout: its handler stays
        yield
        return
    name = "RAY_DISABLE_FAILURE_SIGNAL_HANDLER"
    if not hasattr(ray_constants, name):
        yield
        return
    old = getattr(ray_constants, name)
    setattr(ray_constants, name, True)
    try:
        yield
    finally:
        setattr(ray_constants, name, old)


#: Seconds the probe of a cluster (:func:`_probe_cluster`) waits for a free CPU before the run goes on unprobed.
PROBE_TIMEOUT = 60.0


def _init(**kw: Any) -> None:
    """``ray.init(**kw)``; where it exits instead, Ray is shut down and KeyboardInterrupt raised.

    ``ray.init`` sets its own SIGTERM handler as it starts, unless :meth:`_Stop.kept` holds it off:
    a SIGTERM then ends ``ray.init`` with SystemExit, part of Ray started.
    """
    import ray

    try:
        ray.init(**kw)
    except SystemExit:
        ray.shutdown()
        raise KeyboardInterrupt from None


def _probe_cluster(address: str, init_kw: dict[str, Any], stopped: Callable[[], bool] | None = None) -> bool:
    """Run one small task where the loops' tasks run: valve_gym must import there, the same version as here.

    Where the nodes lack valve_gym itself (``No module named 'valve_gym'``) but have its dependencies,
    this process joins the cluster again with the package sent along (Ray's job-level ``runtime_env``
    ``py_modules``, without compiled caches) and probes again; returns True then.  Without the probe, a
    cluster whose nodes lacked valve_gym (or one of its dependencies) turned every loop into an error row
    that only a Ray traceback explained.  A cluster with no CPU free within :data:`PROBE_TIMEOUT` is not
    probed (the run goes on), nor one whose probe ``stopped`` cuts short.  Raises ValueError saying
    what to install.
    """
    import ray

    import valve_gym

    cause, there = _probe(stopped)
    sent = cause is not None and "No module named 'valve_gym'" in cause
    if sent:
        ray.shutdown()
        _init(address=address, runtime_env={"py_modules": [valve_gym],
                                            "excludes": ["__pycache__", "*.pyc", "*.nbi", "*.nbc"]}, **init_kw)
        cause, there = _probe(stopped)
    version = valve_gym.__version__
    if cause is not None:
        raise ValueError(f"the Ray cluster at {address} cannot run valve_gym's tasks ({cause}"
                         f"{'; valve_gym itself was sent along' if sent else ''}): install valve_gym {version} "
                         f"and its dependencies on every node (the same Python environment as here), or "
                         f"leave out --address to run Ray in this process")
    if there is not None and there != version:
        raise ValueError(f"the Ray cluster at {address} runs valve_gym {there}, this process {version}: "
                         f"install the same version on every node, or leave out --address")
    return sent


def _probe(stopped: Callable[[], bool] | None = None) -> tuple[str | None, str | None]:
    """One probe task: ``(its error's cause or None, valve_gym's version there or None)``.

    ``(None, None)`` when it does not finish within :data:`PROBE_TIMEOUT` or ``stopped()`` turns
    true (looked at each second).
    """
    import ray
    import ray.exceptions

    @ray.remote(num_cpus=1, max_retries=0)
    def probe() -> str:
        import valve_gym
        from valve_gym.fleet import analyse  # noqa: F401  (the fleet's own imports: numba, scipy, pandas)
        return valve_gym.__version__

    ref = probe.remote()
    end = time.perf_counter() + PROBE_TIMEOUT
    try:
        while True:
            ready, _ = ray.wait([ref], timeout=max(0.0, min(1.0, end - time.perf_counter())))
            if ready:
                return None, ray.get(ref)
            if time.perf_counter() >= end or (stopped is not None and stopped()):
                ray.cancel(ref, force=True)
                return None, None
    except ray.exceptions.RayError as e:
        return task_error_cause(e), None


def task_error_cause(e: BaseException) -> str:
    """The last line of a Ray task's error (``ExcType: message``), without the terminal's colour codes."""
    import re

    text = re.sub(r"\x1b\[[0-9;]*m", "", str(e)).strip()
    lines = [ln.strip() for ln in text.splitlines() if ln.strip() and not set(ln.strip()) <= set("^~")]
    return (lines[-1] if lines else type(e).__name__)[:300]


def check_out_dir(path: str, out_dir: str, what: str = "out_dir") -> None:
    """Refuse an output folder that is the input itself, before any work.

    A fleet writes ``loops/``, ``loops.csv``, ``loops.parquet`` and ``worklist.*`` into
    ``out_dir``: written into the input folder they would sit among the recordings, and a
    wide export given as ``path`` could be overwritten by the table.  An ``out_dir`` *inside*
    the input folder is fine: discovery does not look into subfolders.  Paths are compared
    after resolving links (:func:`os.path.realpath`).

    Raises
    ------
    ValueError
        Naming ``what`` (``--out`` on the command line), the clash and what to do.
    """
    src, out = os.path.realpath(path), os.path.realpath(out_dir)
    if os.path.isdir(src) and src == out:
        other = os.path.relpath(os.path.join(os.path.dirname(src), os.path.basename(src) + "-fleet"))
        sub = os.path.normpath(os.path.join(out_dir, "fleet"))
        raise ValueError(f"{what} {out_dir!r} is the input folder itself: the fleet's outputs (loops/, "
                         f"{', '.join(FLEET_OUTPUT_FILES)}) would be written among the recordings; give "
                         f"another folder, e.g. {other!r} (a subfolder such as {sub!r} works too: the "
                         f"loops are not looked for in subfolders)")
    if os.path.isfile(src) and os.path.dirname(src) == out and os.path.basename(src).lower() in FLEET_OUTPUT_FILES:
        raise ValueError(f"{what} {out_dir!r} would overwrite the input {path!r} with the fleet's "
                         f"{os.path.basename(src)}; give another output folder")


class _Stop:
    """Ctrl-C (SIGINT) and SIGTERM during a run: noted, and acted on where stopping is safe.

    Inside ``with _Stop(note) as stop`` (main thread only; a signal that is ignored stays ignored)
    a signal sets :attr:`signum` and tells ``note`` once that the run is stopping; the run looks
    at :attr:`requested` between steps.  Ray is therefore never cut off while it starts or shuts
    down: an interrupted ``ray.init`` left Ray's agent processes running after the command had
    exited, and the driver could crash at exit (SIGSEGV).  A second signal changes nothing: the
    stop is already on its way, except a second Ctrl-C, which raises KeyboardInterrupt at once (for
    a Ray start that hangs; Ray's processes may then be left running).
    """

    SIGNALS = ("SIGINT", "SIGTERM")

    def __init__(self, note: Callable[[str], None] | None = None):
        self.note = note
        self.signum: int | None = None
        self._old: dict = {}
        #: what the run does when a first signal arrives (told to ``note``); the run sets it as it goes on
        self.text = ("stopping: the finished loops are kept, those in flight cancelled; the table and the worklist "
                     "are written and Ray is shut down first (a few seconds; Ctrl-C again to stop at once)")

    @property
    def requested(self) -> bool:
        """Whether a signal has arrived."""
        return self.signum is not None

    def _handler(self, signum, frame) -> None:
        if self.signum is not None:
            if signum == self.signum == signal.SIGINT:
                # Ctrl-C pressed again: the user will not wait (e.g. a Ray start that hangs); stop at once
                self._say("stopping at once (Ctrl-C twice): Ray processes may be left running; `ray stop` ends "
                          "them")
                raise KeyboardInterrupt
            return
        self.signum = signum
        self._say(self.text)

    def _say(self, text: str) -> None:
        if self.note is not None:
            try:
                self.note(text)
            except (OSError, RuntimeError, ValueError):   # the stream busy (a write cut short) or closed
                pass

    def __enter__(self) -> _Stop:
        import threading

        if threading.current_thread() is threading.main_thread():
            for name in self.SIGNALS:
                sig = getattr(signal, name)
                cur = signal.getsignal(sig)
                if cur is not signal.SIG_IGN:
                    self._old[sig] = cur
                    signal.signal(sig, self._handler)
        return self

    def __exit__(self, *exc) -> None:
        for sig, h in self._old.items():
            signal.signal(sig, h if h is not None else signal.SIG_DFL)
        self._old = {}

    @contextlib.contextmanager
    def kept(self) -> Iterator[None]:
        """Within: a handler set for these signals is not set (``ray.init`` sets its own SIGTERM handlers).

        Ray's handler ends ``ray.init`` with SystemExit, part of Ray started, and its crash handler
        (in the core worker) stays in front of this one; :meth:`rearm` puts this one back in front.
        """
        real = signal.signal
        ours = set(self._old)

        def guarded(sig, handler):
            return signal.getsignal(sig) if sig in ours else real(sig, handler)

        signal.signal = guarded
        try:
            yield
        finally:
            signal.signal = real

    def rearm(self) -> None:
        """Install this handler again for each signal it holds (in front of one set outside Python)."""
        for sig in self._old:
            signal.signal(sig, self._handler)


def _collect(ref, src_of: dict, keys: dict) -> LoopResult:
    import ray
    import ray.exceptions

    src = src_of[ref]
    try:
        return ray.get(ref)
    except ray.exceptions.RayError as e:       # a lost worker or node, a cancelled task, a node without valve_gym
        cause = task_error_cause(e)
        if "ModuleNotFoundError" in cause or "ImportError" in cause:
            return failed_result(src, keys[src.name], "error", f"the worker cannot import valve_gym's task "
                                                               f"({cause}); install valve_gym and its dependencies "
                                                               f"on every node, then run again")
        return failed_result(src, keys[src.name], "error", f"worker lost ({type(e).__name__}): {cause}; "
                                                           f"run again to retry")


class _Sink:
    """Where each loop's result goes as it arrives.

    Its JSON (with an output folder), the results, the progress bar, ``on_result``; the table every
    :data:`_TABLE_EVERY_S` seconds.
    """

    def __init__(self, out_dir: str | None, results: dict, bar: Progress,
                 on_result: Callable[[LoopResult], None] | None):
        self.out_dir, self.results, self.bar, self.on_result = out_dir, results, bar, on_result
        self.last_table = time.perf_counter()

    def take(self, res: LoopResult) -> None:
        if self.out_dir is not None:
            write_result(res, os.path.join(self.out_dir, "loops", res.loop + ".json"))
        self.results[res.loop] = res
        self.bar.update(failed=res.status != "ok")
        if self.on_result:
            self.on_result(res)

    def tick(self) -> None:
        if self.out_dir is not None and time.perf_counter() - self.last_table > _TABLE_EVERY_S:
            write_table(list(self.results.values()), self.out_dir)
            self.last_table = time.perf_counter()


def _stream(todo: list[LoopSource], keys: dict, settings: FleetSettings, jobs: int, sink: _Sink,
            ship: bool = False, stop: _Stop | None = None) -> list[LoopSource]:
    """Submit ``todo`` with a bounded window, write each result as it comes; returns the loops not done.

    ``ship``: send each file's bytes with its tasks (a cluster's nodes need not see the files).
    ``stop``: looked at after each result and at least once a second; when requested (or on
    KeyboardInterrupt) the loops in flight are cancelled.
    """
    import ray

    task = _remote(settings)
    shipper = _Shipper(ship)
    cpus = int(ray.cluster_resources().get("CPU", jobs)) or jobs
    window = max(2 * cpus, 4)
    pending = list(reversed(todo))
    src_of: dict = {}
    try:
        while pending or src_of:
            if stop is not None and stop.requested:
                raise KeyboardInterrupt
            while pending and len(src_of) < window:
                s = pending.pop()
                src_of[task.remote(s, keys[s.name], shipper.ref(s))] = s
            ready, _ = ray.wait(list(src_of), num_returns=1, timeout=1.0)
            for ref in ready:
                res = _collect(ref, src_of, keys)
                shipper.done(src_of.pop(ref))
                sink.take(res)
            if not ready:
                sink.bar.show()
            sink.tick()
    except KeyboardInterrupt:
        for ref in src_of:
            ray.cancel(ref, force=True)
        return list(src_of.values()) + list(reversed(pending))
    return []


@contextlib.contextmanager
def _ray_up(jobs: int, address: str | None, say, stop: _Stop) -> Iterator[bool]:
    """Within: Ray started (unless one runs already: yields whether this call started it), shut down after.

    A signal is only noted while Ray starts, which it does without its own crash handler where Ray has a
    switch for it (:func:`_signals_left_to_python`).  Without the switch, Ray's core worker leaves SIGTERM
    to its default action as it shuts down (a SIGTERM in that second ended the command with 143): so the
    table and the worklist are written before this context ends, and the handler is put back in front
    after it.
    """
    started = False
    try:
        with stop.kept():
            started = _start_ray(jobs, address, say, lambda: stop.requested)  # refused: nothing on disk
        stop.rearm()
        yield started
    finally:
        if started:
            import ray
            ray.shutdown()
            stop.rearm()


def _worker_init(threads: int) -> None:
    """A local worker process: its share of the kernel threads; Ctrl-C is the driver's to act on."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    from ..diagnosis.model import set_kernel_threads
    set_kernel_threads(threads)


def _local_task(args: tuple[LoopSource, FleetSettings, str]) -> LoopResult:
    src, settings, key = args
    return analyse_loop(src, settings, key)


def local_results(fn: Callable[[Any], Any], items: list, jobs: int, stop: Callable[[], bool] | None = None
                  ) -> Generator[tuple[int, Any, BaseException | None], None, None]:
    """``fn`` over ``items`` without Ray: ``(index, result, None)``, or ``(index, None, error)``, as each finishes.

    The local executor of the batch engine: with ``jobs`` 1 (or one item) the items run one after another
    in this process, in order (an exception of ``fn`` propagates); otherwise in ``jobs`` worker processes
    (``fn`` and the items picklable; each worker gets its share of the kernel threads and leaves Ctrl-C to
    this process), at most ``2 jobs`` submitted at once, an error of a worker (a lost process) is
    yielded, and ``(-1, None, None)`` when no item finished within a second (for a progress line).
    ``stop()`` is looked at before each item and at least once a second; when it is true, or when the
    caller stops iterating (``close()``), the items not finished are given up (the workers ended).
    """
    if jobs <= 1 or len(items) <= 1:
        for i, it in enumerate(items):
            if stop is not None and stop():
                return
            yield i, fn(it), None
        return
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    from ..diagnosis.model import kernel_threads

    ex = ProcessPoolExecutor(max_workers=jobs, initializer=_worker_init,
                             initargs=(max(1, kernel_threads() // jobs),))
    pending = list(reversed(range(len(items))))
    index_of: dict = {}
    finished = False
    try:
        while pending or index_of:
            if stop is not None and stop():
                return
            while pending and len(index_of) < 2 * jobs:
                i = pending.pop()
                index_of[ex.submit(fn, items[i])] = i
            ready, _ = wait(list(index_of), timeout=1.0, return_when=FIRST_COMPLETED)
            for fu in ready:
                i = index_of.pop(fu)
                try:
                    yield i, fu.result(), None
                except Exception as e:              # a worker process lost (killed, out of memory)
                    yield i, None, e
            if not ready:
                yield -1, None, None                # nothing finished within the second
        finished = True
    finally:
        if not finished:
            for proc in list((getattr(ex, "_processes", None) or {}).values()):
                with contextlib.suppress(Exception):
                    proc.terminate()
        ex.shutdown(wait=True, cancel_futures=True)


def _run_local(todo: list[LoopSource], keys: dict, settings: FleetSettings, jobs: int, sink: _Sink,
               stop: _Stop) -> list[LoopSource]:
    """Run ``todo`` without Ray (:func:`local_results`); returns the loops not done.

    After a signal the loop in progress in this process is finished (unless Ctrl-C comes twice), the
    workers' loops are given up.
    """
    done: set[int] = set()
    results = local_results(_local_task, [(s, settings, keys[s.name]) for s in todo], jobs, lambda: stop.requested)
    try:
        for i, res, err in results:
            if i < 0:
                sink.bar.show()
                continue
            if err is not None:
                s = todo[i]
                res = failed_result(s, keys[s.name], "error", f"worker lost ({type(err).__name__}: {err}); "
                                                              f"run again to retry")
            done.add(i)
            sink.take(res)
            sink.tick()
    except KeyboardInterrupt:                       # Ctrl-C twice: the loop in progress is given up
        pass
    finally:
        results.close()                             # the workers' loops not finished are given up
    return [s for i, s in enumerate(todo) if i not in done]


def _run_todo(todo, keys, settings, jobs, address, engine: str, sink: _Sink, stream, stop: _Stop,
              ray_stack: contextlib.ExitStack) -> list[LoopSource]:
    """Run the loops of ``todo`` on ``engine``; the loops left.

    ``'ray'``: Ray started on ``ray_stack`` (shut down when it closes); all of the loops are left when a
    signal came while Ray started.  ``'local'``: :func:`_run_local`.
    """
    say = None if stream is None else (lambda m: print(m, file=stream, flush=True))
    try:
        if sink.out_dir is not None:
            os.makedirs(os.path.join(sink.out_dir, "loops"), exist_ok=True)
        if engine == "local":
            return _run_local(todo, keys, settings, jobs, sink, stop)
        started = ray_stack.enter_context(_ray_up(jobs, address, say, stop))
        if stop.requested:
            return list(todo)
        return _stream(todo, keys, settings, jobs, sink, ship=bool(address) or not started, stop=stop)
    except KeyboardInterrupt:       # while Ray started (or its start was cut short): no loop ran
        return list(todo)
    finally:
        sink.bar.close()


#: Engines of :func:`run_fleet`: ``'local'`` (this process, or local worker processes; no Ray), ``'ray'``,
#: ``'auto'`` (Ray where an address is given, else local).
ENGINES = ("auto", "local", "ray")


def run_fleet(path: str, out_dir: str | None, settings: FleetSettings = FleetSettings(), jobs: int = 2,
              address: str | None = None, max_loops: int | None = None, stream=sys.stderr,
              top: int = 10, on_result: Callable[[LoopResult], None] | None = None,
              engine: str = "auto") -> FleetRun:
    """Diagnose every loop of ``path``, streaming results into ``out_dir``.

    The one batch engine of valve_gym: ``valve-gym diagnose DIR`` (with or without ``--out``) runs it.
    Each loop is screened and, where it oscillates (or ``settings.full``), diagnosed in full
    (:func:`~valve_gym.fleet.analyse.analyse_loop`); the same work whichever engine runs it.

    Ctrl-C (SIGINT) or SIGTERM during the run (main thread): the loops in flight are given up (Ray's
    cancelled, local workers ended; in this process the loop in progress is finished first, unless
    Ctrl-C comes twice), the table and the worklist of the finished loops are written, Ray (if started)
    is shut down and the result says ``interrupted``; a signal while Ray starts takes effect once it is
    up, one while the table and the worklist are written once they are (both written whole).  Before
    that (finding the loops) KeyboardInterrupt is raised as usual.  Every finished loop is in
    ``out_dir/loops/`` already.

    Parameters
    ----------
    path : str, a folder of recordings / wide exports, or one wide export
    out_dir : str or None, output folder (created); ``loops/``, ``loops.csv``, ``loops.parquet`` (with
        pyarrow), ``worklist.md``, ``worklist.html``.  None: nothing is written and nothing resumed (the
        results are returned)
    settings : FleetSettings
    jobs : int, workers on this machine: with the local engine 1 runs the loops one after another in
        this process, more in as many local worker processes; with Ray its workers (ignored with
        ``address``)
    address : str, optional, address of an existing Ray cluster (``'auto'`` or ``'host:port'``)
    max_loops : int, optional, analyse at most this many new loops in this call (the rest next time)
    stream : text stream for the progress bar, None for silence
    top : int, loops with plots in the HTML worklist
    on_result : callable(LoopResult), optional, told of each result as it arrives
    engine : {'auto', 'local', 'ray'}, ``'local'``: no Ray needed; ``'ray'``: Ray tasks (in this process
        with ``jobs`` workers, or on the cluster at ``address``; needs the ``[fleet]`` extra); ``'auto'``
        (default): Ray where ``address`` is given, else local

    Returns
    -------
    FleetRun

    Raises
    ------
    ValueError
        ``jobs`` < 1, an unknown ``engine``, ``address`` with the local engine, or ``out_dir`` is the
        input folder itself (:func:`check_out_dir`), before any work; RecordingError (a ValueError)
        when ``path`` holds no loops.
    """
    from .worklist import write_worklist

    t0 = time.perf_counter()
    if jobs < 1:
        raise ValueError(f"jobs must be at least 1, got {jobs!r}")
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    if engine == "auto":
        engine = "ray" if address else "local"
    if engine == "local" and address:
        raise ValueError(f"address {address!r} names a Ray cluster: use engine='ray' (or 'auto')")
    if out_dir is not None:
        check_out_dir(path, out_dir)
    sources = discover_loops(path)
    skipped = fleet_outputs(path)
    if skipped and stream is not None:
        print(f"note: skipped {', '.join(os.path.basename(f) for f in skipped)} in {path}: the outputs of an "
              f"earlier fleet run, not recordings", file=stream, flush=True)
    if out_dir is not None:
        keys, stored, todo = plan_fleet(sources, out_dir, settings)
    else:
        keys = {s.name: loop_key(s.fingerprint, s.kind, s.tag, settings) for s in sources}
        stored, todo = {}, list(sources)
    later: list[LoopSource] = []
    if max_loops is not None:
        todo, later = todo[:max_loops], todo[max_loops:]
    results: dict[str, LoopResult] = dict(stored)
    bar = Progress(len(todo), skipped=len(stored), stream=stream)
    sink = _Sink(out_dir, results, bar, on_result)
    left: list[LoopSource] = []
    paths: dict[str, str] = {}
    # signals noted, acted on between steps; the table and the worklist are written whole either way, before
    # Ray is shut down (the ExitStack closes first)
    with _Stop(None if stream is None else bar.note) as stop, contextlib.ExitStack() as ray_stack:
        if engine == "local":
            stop.text = ("stopping: the finished loops are kept, " + (
                "the loop in progress is finished first" if jobs <= 1 else "those in flight given up") +
                "; the table and the worklist are written (Ctrl-C again to stop at once)")
        if todo:
            left = _run_todo(todo, keys, settings, jobs, address, engine, sink, stream, stop, ray_stack)
        stop.text = "stopping once the table and the worklist are written (a few seconds)"
        ordered = apply_shared_periods([results[s.name] for s in sources if s.name in results])
        remaining = len(left) + len(later)
        if out_dir is not None:
            p_table, p_csv = write_table(ordered, out_dir)
            md, html = write_worklist(ordered, sources, out_dir, settings, top=top, pending=remaining)
            paths = {"table": p_table, "csv": p_csv, "worklist_md": md, "worklist_html": html}
    n_failed = sum(r.status != "ok" for r in ordered)
    return FleetRun(len(sources), len(todo) - len(left), len(stored), n_failed, bool(left) or stop.requested,
                    remaining, time.perf_counter() - t0, ordered, paths)
