"""Threads of one model (private; used by :class:`asnn.model.ASNN` with ``threads`` > 1).

:class:`BandedFront` computes :func:`asnn._fast.front` in bands of rows, one per thread, and
moves the bands' borders from frame to frame so that the other threads are done about when the
calling thread needs their bands: every pixel is computed the same way whatever the bands, so
where the borders lie changes nothing in the results, only in the time.

Band servers
------------
The threads other than the calling one are band servers (:class:`_Server`): each stays in one
numba kernel call (:func:`_serve`) for the life of the front. It computes its band of a pass,
marks it done in a counter shared with the calling thread, and waits for the next pass. The
calling thread hands over a pass by writing its data into one of :data:`SLOTS` slots and its
number into the counters, and waits for the servers' bands in a kernel too. Either side waits
by polling the counters for up to :data:`SPIN` seconds, then sleeps on a futex that the other
side wakes: neither needs the GIL, and a thread is woken by the operating system only after it
had nothing to do for a while.

Why: with a Python thread per band call, the worker slept on a queue between frames and
needed the GIL to start a band and again to return from it. The operating system takes tens
of microseconds to wake a thread (about 70 us on the virtual machine of the README's figures),
and the GIL is only handed over when the thread stepping the model (Python most of the time:
attention, objects, output) lets go of it: each frame's band started 0.1-0.2 ms late at
320x240, of about 1.4 ms per frame. Polling alone is no answer either: on a machine whose
cores other processes use, a polling thread takes their time (measured: 4 ms per frame instead
of 2.6 with one other busy process), hence the short :data:`SPIN` and the futex.

The counters are read and written atomically, sequentially consistent (:func:`_load`,
:func:`_store`): the data of a pass are written before its number, a band's maps before its
done mark, and a thread about to sleep announces it before it looks a last time, while the
other side writes before it looks whether to wake it, so no wake-up is lost. Futexes are
Linux's; elsewhere the model computes on one thread (:func:`supported`).
"""

from __future__ import annotations

import platform
import queue
import sys
import threading
import time
from collections import deque

import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from . import _fast
from ._jit import kernel

__all__ = ["BandedFront", "SLOTS", "SPIN", "supported"]

SLOTS = 3  # passes whose data and maps live at once: two frames being finished and the next
SPIN = 100e-6  # seconds a thread polls for a pass or a band before it sleeps
_NAP = 10_000_000  # nanoseconds a sleeping thread sleeps at most before it looks again
_LEAVE = 50_000_000  # nanoseconds without a pass after which a server leaves its kernel
_LIVENESS = 100_000_000  # nanoseconds the calling thread waits for bands before it looks
# whether the servers' threads still run (one that ended never finishes its band)

# the shared counters, per server: the latest pass handed to it, the latest it finished, and
# flags: told to leave its kernel (EXIT), failed (FAILED), in its kernel (RUNNING), asleep
# (SLEEPING); after the servers' rows, whether the calling thread sleeps
_REQUESTED, _DONE, _EXIT, _FAILED, _RUNNING, _SLEEPING = range(6)
_FIELDS = 6

_ARCH = platform.machine().lower()
_SYS_FUTEX = {"x86_64": 202, "amd64": 202, "aarch64": 98, "arm64": 98}.get(_ARCH)
_FUTEX_WAIT, _FUTEX_WAKE = 128, 129  # FUTEX_WAIT, FUTEX_WAKE | FUTEX_PRIVATE_FLAG
_MONOTONIC = getattr(time, "CLOCK_MONOTONIC", 1)
_THREAD_CPU = getattr(time, "CLOCK_THREAD_CPUTIME_ID", 3)


def supported() -> bool:
    """Whether band servers can run here (Linux on x86-64 or Arm64: futexes and POSIX
    clocks)."""
    return sys.platform.startswith("linux") and _SYS_FUTEX is not None


# --------------------------------------------------------------------------- kernel helpers


def _item_pointer(context, builder, array_type, array, index):
    return cgutils.get_item_pointer(context, builder, array_type,
                                    context.make_array(array_type)(context, builder, array),
                                    [index])


@intrinsic
def _load(typingctx, array, index):
    """``array[index]`` of a 1-D integer array, read atomically (sequentially consistent)."""
    def codegen(context, builder, signature, args):
        ptr = _item_pointer(context, builder, signature.args[0], args[0], args[1])
        return builder.load_atomic(ptr, "seq_cst", array.dtype.bitwidth // 8)

    return array.dtype(array, index), codegen


@intrinsic
def _store(typingctx, array, index, value):
    """``array[index] = value`` in a 1-D int64 array, written atomically (sequentially
    consistent)."""
    def codegen(context, builder, signature, args):
        ptr = _item_pointer(context, builder, signature.args[0], args[0], args[1])
        builder.store_atomic(args[2], ptr, "seq_cst", 8)
        return context.get_dummy_value()

    return types.none(array, index, value), codegen


@intrinsic
def _ring(typingctx, bells, index):
    """Add 1 to the futex word ``bells[index]`` (int32) and wake the thread sleeping on it."""
    def codegen(context, builder, signature, args):
        i32, i64 = ir.IntType(32), ir.IntType(64)
        ptr = _item_pointer(context, builder, signature.args[0], args[0], args[1])
        builder.atomic_rmw("add", ptr, ir.Constant(i32, 1), "seq_cst")
        _futex(builder, ptr, _FUTEX_WAKE, ir.Constant(i64, 1), None)
        return context.get_dummy_value()

    return types.none(bells, index), codegen


@intrinsic
def _sleep_on(typingctx, bells, index, seen):
    """Sleep while the futex word ``bells[index]`` (int32) still holds ``seen``, until woken,
    for at most ``_NAP`` nanoseconds."""
    def codegen(context, builder, signature, args):
        i64 = ir.IntType(64)
        ptr = _item_pointer(context, builder, signature.args[0], args[0], args[1])
        nap = cgutils.alloca_once(builder, ir.ArrayType(i64, 2))  # struct timespec
        builder.store(ir.Constant(ir.ArrayType(i64, 2), [_NAP // 1_000_000_000,
                                                         _NAP % 1_000_000_000]), nap)
        _futex(builder, ptr, _FUTEX_WAIT, builder.sext(args[2], i64), nap)
        return context.get_dummy_value()

    return types.none(bells, index, seen), codegen


def _futex(builder, word, operation, value, timeout):
    """``syscall(SYS_futex, word, operation, value, timeout, NULL, 0)`` (the C library's
    ``syscall``, called by name)."""
    i64 = ir.IntType(64)
    fn = cgutils.get_or_insert_function(builder.module,
                                        ir.FunctionType(i64, [i64], var_arg=True), "syscall")
    null = ir.Constant(i64, 0)
    builder.call(fn, [ir.Constant(i64, _SYS_FUTEX or 0), builder.ptrtoint(word, i64),
                      ir.Constant(i64, operation), value,
                      null if timeout is None else builder.ptrtoint(timeout, i64), null, null])


@intrinsic
def _clock_ns(typingctx, clock):
    """``clock_gettime(clock)`` in nanoseconds (the C library's, called by name)."""
    def codegen(context, builder, signature, args):
        i64, i32 = ir.IntType(64), ir.IntType(32)
        spec = cgutils.alloca_once(builder, ir.ArrayType(i64, 2))  # struct timespec
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(i32, [i32, spec.type]),
                                            "clock_gettime")
        builder.call(fn, [builder.trunc(args[0], i32), spec])
        zero, one = ir.Constant(i32, 0), ir.Constant(i32, 1)
        seconds = builder.load(builder.gep(spec, [zero, zero]))
        nanoseconds = builder.load(builder.gep(spec, [zero, one]))
        return builder.add(builder.mul(seconds, ir.Constant(i64, 1_000_000_000)), nanoseconds)

    return types.int64(clock), codegen


@intrinsic
def _pause(typingctx):
    """The processor's hint that this is a polling loop (x86 ``pause``, Arm ``yield``): the
    loop then takes less from a thread that shares the core with it."""
    def codegen(context, builder, signature, args):
        void = ir.FunctionType(ir.VoidType(), [])
        if _ARCH in ("x86_64", "amd64"):
            builder.call(builder.module.declare_intrinsic("llvm.x86.sse2.pause", fnty=void), [])
        elif _ARCH in ("aarch64", "arm64"):
            i32 = ir.IntType(32)
            hint = builder.module.declare_intrinsic(
                "llvm.aarch64.hint", fnty=ir.FunctionType(ir.VoidType(), [i32]))
            builder.call(hint, [ir.Constant(i32, 1)])  # yield
        return context.get_dummy_value()

    return types.none(), codegen


@kernel()
def _post(control, bells, number, out):
    """Hand pass ``number`` to every server (its data are written), waking those asleep;
    ``out[server]`` is set to whether it is out of its kernel (it left, see :func:`_serve`)."""
    for server in range(len(bells) - 1):
        _store(control, server * _FIELDS + _REQUESTED, number)
        if _load(control, server * _FIELDS + _SLEEPING) != 0:
            _ring(bells, server)
        out[server] = _load(control, server * _FIELDS + _RUNNING) == 0


@kernel()
def _tell(control, bells, server, field, value):
    """Set a server's flag (EXIT, FAILED) and wake every thread, which then looks at it."""
    _store(control, server * _FIELDS + field, value)
    for k in range(len(bells)):
        _ring(bells, k)


@kernel()
def _await_servers(control, servers, spin_ns):
    """Poll until every server is in its kernel (True), or ``spin_ns`` passed (False)."""
    start = _clock_ns(_MONOTONIC)
    for server in range(servers):
        while _load(control, server * _FIELDS + _RUNNING) == 0:
            if _clock_ns(_MONOTONIC) - start > spin_ns:
                return False
            _pause()
    return True


@kernel()
def _finished(control, servers, number):
    """1 if every server has finished pass ``number``, -1 if one failed, else 0."""
    finished = 0
    for server in range(servers):
        if _load(control, server * _FIELDS + _FAILED) != 0:
            return -1
        finished += _load(control, server * _FIELDS + _DONE) >= number
    return 1 if finished == servers else 0


@kernel()
def _await_pass(control, bells, number, spin_ns, limit_ns):
    """Wait until every server has finished pass ``number`` (1) or one failed (-1), or for
    ``limit_ns`` at most (0): polling for ``spin_ns``, then asleep until a server wakes this
    thread (see :func:`_serve`) or ``_NAP`` passed."""
    servers = len(bells) - 1
    me = servers * _FIELDS  # the calling thread's flag after the servers' rows
    start = _clock_ns(_MONOTONIC)
    while True:
        state = _finished(control, servers, number)
        if state != 0:
            return state
        waited = _clock_ns(_MONOTONIC) - start
        if waited > limit_ns:
            return 0
        if waited <= spin_ns:
            _pause()
            continue
        seen = _load(bells, servers)
        _store(control, me + _SLEEPING, 1)
        if _finished(control, servers, number) == 0:
            _sleep_on(bells, servers, seen)
        _store(control, me + _SLEEPING, 0)


@kernel(boundscheck=False)
def _serve(control, bells, server, spin_ns, params, timing, photos, versions, stages_on,
           stages_off, other_on, other_off, env, sc, a, b, e_x, j, gain, n_fast, n_slow, swap,
           gk, vw, kc, aw, terms, grouping, zero, tiny, ninth, col, x0, ro, gabor, acc, csl,
           gring, gline, spare_on, spare_off, r, v, g, colsum, done):
    """A server's bands of the passes handed to it, in order, until it is told to leave.
    Pass k's data are slot ``k % SLOTS`` of ``params`` (this server's rows (y0, y1) and whether
    its band sets the column sums), ``photos``, ``versions`` and the maps (``r``, ``v``, ``g``,
    ``colsum``); ``timing[server, slot]`` gets the band's start (monotonic clock) and processor
    time, in nanoseconds. Between passes it polls for ``spin_ns``, then sleeps on its futex
    word ``bells[server]`` until :func:`_post` wakes it, and after ``_LEAVE`` nanoseconds
    without a pass it returns (an idle model's thread then waits in Python, at no cost); once a
    band is done, it wakes the calling thread if that sleeps (:func:`_await_pass`)."""
    me = server * _FIELDS
    servers = len(bells) - 1
    caller = servers * _FIELDS
    served = control[me + _DONE]
    _store(control, me + _RUNNING, 1)
    idle = _clock_ns(_MONOTONIC)
    while _load(control, me + _EXIT) == 0:
        k = served + 1
        if _load(control, me + _REQUESTED) < k:
            waited = _clock_ns(_MONOTONIC) - idle
            if waited <= spin_ns:
                _pause()
                continue
            if waited > _LEAVE:
                # leave unless a pass came meanwhile: _post writes its number, then reads
                # RUNNING; this thread the other way round, so one sees the other's write
                _store(control, me + _RUNNING, 0)
                if _load(control, me + _REQUESTED) < k:
                    return
                _store(control, me + _RUNNING, 1)
                continue
            seen = _load(bells, server)
            _store(control, me + _SLEEPING, 1)
            if _load(control, me + _REQUESTED) < k and _load(control, me + _EXIT) == 0:
                _sleep_on(bells, server, seen)
            _store(control, me + _SLEEPING, 0)
            continue
        # the bands of pass k read the rows that every band of pass k - 1 wrote (the calling
        # thread's was done before k was handed out)
        for other in range(servers):
            while _load(control, other * _FIELDS + _DONE) < k - 1:
                if _load(control, other * _FIELDS + _FAILED) != 0 or \
                        _load(control, me + _EXIT) != 0:
                    _store(control, me + _RUNNING, 0)
                    return
                _pause()
        s = k % SLOTS
        y0, y1 = params[server, s, 0], params[server, s, 1]
        timing[server, s, 0] = _clock_ns(_MONOTONIC)
        cpu = _clock_ns(_THREAD_CPU)
        if y0 < y1:
            _fast._front(photos[s], env, sc, stages_on, stages_off, other_on, other_off,
                         versions[s, 0], versions[s, 1], a, b, e_x, j, gain, n_fast, n_slow,
                         swap, gk, vw, kc, aw, terms, grouping, zero, tiny, ninth, col, x0, ro,
                         gabor, acc, csl, gring, gline, spare_on, spare_off, r[s], v[s], g[s],
                         colsum[s], y0, y1, params[server, s, 2] != 0, done)
        timing[server, s, 1] = _clock_ns(_THREAD_CPU) - cpu
        served = k
        _store(control, me + _DONE, k)
        if _load(control, caller + _SLEEPING) != 0:
            _ring(bells, servers)
        idle = _clock_ns(_MONOTONIC)
    _store(control, me + _RUNNING, 0)


# --------------------------------------------------------------------------- servers


class _Server:
    """A thread that runs :func:`_serve` whenever it is handed a pass it has not served."""

    def __init__(self, front: "BandedFront", index: int):
        self.index = index
        self.error: BaseException | None = None
        self.lock = threading.Lock()  # held while in the kernel (see BandedFront._bind)
        self._tokens: queue.SimpleQueue = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._run, args=(front,), daemon=True,
                                        name=f"asnn-model-{index + 1}")
        self._thread.start()

    @property
    def name(self) -> str:
        return self._thread.name

    def alive(self) -> bool:
        """Whether the thread still runs (it ends when told to stop, or when it dies)."""
        return self._thread.is_alive()

    def wake(self, number: int | None) -> None:
        """Pass ``number`` is handed out while the thread is out of its kernel (None: stop):
        it goes back in (a token of a pass it served meanwhile is dropped)."""
        self._tokens.put(number)

    def _run(self, front: "BandedFront") -> None:
        control = front.control
        while (number := self._tokens.get()) is not None:
            if number <= control[self.index * _FIELDS + _DONE] or self.error is not None:
                continue
            with self.lock:
                try:
                    _serve(control, front.bells, self.index, int(SPIN * 1e9),
                           *front.arguments[self.index])
                except BaseException as exc:  # raised on the thread that waits for the band
                    self.error = exc
                    _tell(control, front.bells, self.index, _FAILED, 1)


class _Pass:
    """One frame's fused pass in flight (see :class:`BandedFront`)."""

    __slots__ = ("number", "p", "stages", "versions", "maps", "borders", "submitted",
                 "overlapped", "own")

    def __init__(self, number, p, stages, versions, maps, borders, submitted, overlapped):
        self.number, self.p, self.stages, self.versions = number, p, stages, versions
        self.maps, self.borders = maps, borders
        self.submitted, self.overlapped = submitted, overlapped
        self.own: tuple[float, float] | None = None  # the calling thread's (other work, band)


class BandedFront:
    """:func:`asnn._fast.front` over one band of rows per thread: one per server from the top,
    and the calling thread's at the bottom.

    Each band advances its own rows of the cascades (and, again, the few rows beyond it that
    its filters read, which it drops), so the bands of a frame need nothing from each other;
    the next frame's bands need the whole of this one's. A band advances its rows in place,
    except the rows that a neighbouring band reads, which it writes into a second pair of
    arrays (:attr:`other`): the neighbour still reads them as they were. Where each row's state
    is, in the cascades or the second pair, is kept per row (:meth:`settle` brings it all back
    into the cascades). :meth:`start` hands the servers their bands, :meth:`run_own` computes
    the calling thread's, and :meth:`join` waits for the servers' and completes the column sums
    of R^theta: the first band sets them, the others' rows are added in row order, so they are
    those of one pass. A frame's pass may be started before the previous one is joined: a
    server's band waits for the previous pass's bands on the other servers. Bands are at least
    ``2 halo + 2`` rows high; a frame too small for that has fewer bands (the other servers
    get none).

    The borders follow the threads' speeds and the calling thread's other work (finishing
    frames, taking the next one): the bands are sized so that the servers would have been done
    with the latest frame a little before the calling thread needs them. When that other work
    alone takes longer than the servers need for the whole frame, the calling thread's band is
    empty (``borders[-2] == borders[-1]``): a band of the minimum height would only lengthen
    the calling thread's frame, which is then the slower one (its rows cost it more than they
    cost a server: they come after its other work, out of its caches).

    Parameters
    ----------
    coefficients : asnn._fast.FrontCoefficients
    servers : int
        Threads besides the calling one (at least 1).
    """

    _SMOOTHING = 0.25  # weight of the latest frame in the running estimates
    _MARGIN = 50e-6  # seconds a server should be done before its band is needed

    def __init__(self, coefficients: _fast.FrontCoefficients, servers: int):
        self.coefficients = coefficients
        self._min_rows = 2 * coefficients.halo + 2
        # the servers' rows of counters and flags, then the calling thread's (SLEEPING), and
        # the futex words the threads sleep on (the servers', then the calling thread's)
        self.control = np.zeros((servers + 1) * _FIELDS, np.int64)
        self.bells = np.zeros(servers + 1, np.int32)
        self._out = np.zeros(servers, np.bool_)  # servers out of their kernels (see start)
        self.arguments: list[tuple] = []  # the kernel's arguments after the first three
        self._passes = 0  # passes handed out
        # per thread (the servers', then the calling thread's): seconds of other work per
        # frame and seconds per row of band
        self._other = [0.0] * (servers + 1)
        self._cost = [0.0] * (servers + 1)
        self._borders: list[int] | None = None
        self._flight: deque[_Pass] = deque()  # started, not joined yet
        self._bound: tuple | None = None  # what the arguments were made for
        self._own_end: float | None = None  # when the calling thread's latest band ended
        self._waited = 0.0  # seconds it waited in join() since
        self._servers = [_Server(self, k) for k in range(servers)]

    def served(self, server: int) -> int:
        """The latest pass a server has finished (passes are numbered from 1 in the order they
        were started; ``flight.number``)."""
        return int(self.control[server * _FIELDS + _DONE])

    @property
    def failed(self) -> bool:
        """Whether a server failed (its error was raised by :meth:`join`); the front is then of
        no further use."""
        return any(s.error is not None for s in self._servers)

    def close(self) -> None:
        """Stop the servers (they leave their kernels at once)."""
        self._tell_servers(_EXIT, 1)
        for s in self._servers:
            s.wake(None)

    def _tell_servers(self, field: int, value: int) -> None:
        """Set a flag (EXIT) of every server, and wake them to look at it."""
        for s in self._servers:
            _tell(self.control, self.bells, s.index, field, value)

    def borders(self, height: int) -> list[int]:
        """Where the bands of a frame of this height start (the last band the calling
        thread's), and the height."""
        n = min(len(self._servers) + 1, height // self._min_rows)
        if n < 2:
            return [0, height]
        if self._borders is not None and self._borders[-1] == height \
                and len(self._borders) == n + 1:
            return self._borders
        return [round(i * height / n) for i in range(n + 1)]

    def _bind(self, stages: tuple) -> None:
        """Buffers for the cascades ``stages`` (a new stream, or another size): the second pair
        of arrays, the slots, and the servers' kernel arguments, with the servers out of their
        kernels while they change."""
        on, off = stages
        key = (id(on), id(off), on.shape, on.dtype)
        if key == self._bound:
            return
        try:
            self._tell_servers(_EXIT, 1)
            # each lock in a with statement: a KeyboardInterrupt between an acquire and a
            # try: block left one held for good (the next new stream waited for it forever)
            self._with_servers_out(list(self._servers), lambda: self._rebind(on, off, key))
        finally:
            self._tell_servers(_EXIT, 0)

    def _with_servers_out(self, servers: list, body) -> None:
        if not servers:
            return body()
        with servers[0].lock:
            return self._with_servers_out(servers[1:], body)

    def _rebind(self, on, off, key) -> None:
        h, w = on.shape[1:]
        t = on.dtype
        self.other = (np.zeros_like(on), np.zeros_like(off))
        self.maps, stacked = _fast.FrontMaps.slots(SLOTS, (h, w), t)
        self._photos = np.empty((SLOTS, h, w), t)
        self._photo_slots = list(self._photos)  # the slots handed out (next_photo)
        self._versions = np.zeros((SLOTS, 2, h), np.int8)  # per pass: read, write
        self._state = np.zeros(h, np.int8)  # where each row's state is after the passes
        self._params = np.zeros((len(self._servers), SLOTS, 3), np.int64)
        self._timing = np.zeros((len(self._servers), SLOTS, 2), np.int64)
        c = self.coefficients
        self.arguments = []
        for s in self._servers:
            # the servers' ring buffers: made here, used only by their threads
            scratch = _fast.Scratch(w, t)
            self.arguments.append((
                self._params, self._timing, self._photos, self._versions, on, off,
                *self.other, c.env, c.scales, *c[2:], *scratch.buffers(),
                *scratch.spare(on.shape[0]), *stacked, scratch.done))
        self._bound = key

    def start(self, p: np.ndarray, stages: tuple, overlapped: bool = False) -> _Pass:
        """Start a frame's pass: hand the servers their bands.

        ``stages`` are the cascades; ``overlapped`` says that the calling thread finishes
        another frame while the servers compute (for the borders). The pass's maps are
        ``flight.maps``, valid until :data:`SLOTS` passes later.
        """
        if self._flight and self._flight[-1].own is None:
            raise RuntimeError("run_own() the previous pass first")
        self._bind(stages)
        h, w = p.shape
        borders = self.borders(h)
        c = self.coefficients
        self._passes += 1
        number = self._passes
        slot = number % SLOTS
        read, write = self._versions[slot]
        read[:] = self._state
        write[:] = self._state
        for m in borders[1:-1]:  # the rows two bands read go where the other band does not
            if m < h:  # (no band below an empty last one)
                write[m - c.halo:m + c.halo] ^= 1
        self._state = write
        if p is not self._photo_slots[slot]:
            np.copyto(self._photos[slot], p)
        for i in range(len(self._servers)):
            band = (borders[i], borders[i + 1]) if i < len(borders) - 2 else (0, 0)
            self._params[i, slot] = (*band, i == 0)
        flight = _Pass(number, self._photos[slot], stages, (read, write), self.maps[slot],
                       borders, time.monotonic_ns(), overlapped)
        _post(self.control, self.bells, number, self._out)
        if self._out.any():
            # a server out of its kernel (a new stream, or idle for a while) needs the GIL to
            # go back in: let go of it until it is (this thread would otherwise keep it for
            # milliseconds, see the module notes)
            for s in self._servers:
                if self._out[s.index]:
                    s.wake(number)
            _await_servers(self.control, len(self._servers), _NAP)
        self._flight.append(flight)
        return flight

    def next_photo(self, stages: tuple) -> np.ndarray:
        """Where the next pass started for the cascades ``stages`` reads its photoreceptor
        output: P written there is not copied again (:meth:`start`). Valid until that pass
        is started."""
        self._bind(stages)
        return self._photo_slots[(self._passes + 1) % SLOTS]

    def settle(self, stages: tuple) -> None:
        """Bring every row's state back into the cascades (no pass in flight)."""
        if self._flight:
            raise RuntimeError("join() the passes in flight first")
        if self._bound is None:
            return
        there = np.flatnonzero(self._state)
        for s, o in zip(stages, self.other):
            s[:, there] = o[:, there]
        self._state[there] = 0

    def run_own(self, flight: _Pass) -> None:
        """Compute the calling thread's band of a started pass (the pass before it joined)."""
        begun = time.perf_counter()
        other = 0.0
        if flight.overlapped and self._own_end is not None:
            other = begun - self._own_end - self._waited
        borders = flight.borders
        cpu = time.thread_time()
        if borders[-2] < borders[-1]:
            _fast.front(flight.p, flight.stages, self.coefficients, flight.maps,
                        _fast.scratch(flight.p.shape[1], flight.p.dtype),
                        (borders[-2], borders[-1]), self.other, flight.versions,
                        sums=len(borders) == 2)
        flight.own = (other, time.thread_time() - cpu)
        self._own_end = time.perf_counter()
        self._waited = 0.0

    def _wait(self, number: int) -> None:
        """Wait until every server has finished pass ``number``; raise a server's error, or a
        RuntimeError where a server's thread ended without finishing its band (waited for in
        the kernel alone, the calling thread slept on for ever)."""
        while (state := _await_pass(self.control, self.bells, number, int(SPIN * 1e9),
                                    _LIVENESS)) == 0:
            for s in self._servers:
                # dead first: a band it finished before it ended is then seen as served
                if not s.alive() and self.served(s.index) < number and s.error is None:
                    s.error = RuntimeError(
                        f"the ASNN model's worker thread {s.name} ended without computing its "
                        f"band of a frame (pass {number}), so that frame was not stepped; "
                        "reset() the model: it starts new worker threads at its next step")
                    state = -1
            if state < 0:
                break
        if state < 0:
            self._stop_serving()
            raise next(s.error for s in self._servers if s.error is not None)

    def _stop_serving(self) -> None:
        """After a server's failure: every server out of its kernel (none writes on)."""
        self._tell_servers(_EXIT, 1)
        for s in self._servers:
            with s.lock:
                pass

    def join(self, flight: _Pass) -> None:
        """Wait for the servers' bands of a pass (raising a band's exception) and complete its
        column sums. Passes are joined in the order they were started."""
        if not self._flight or self._flight[0] is not flight:
            raise RuntimeError("passes are joined in the order they were started")
        self._flight.popleft()
        waiting = time.perf_counter()
        self._wait(flight.number)
        self._waited += time.perf_counter() - waiting
        borders = flight.borders
        for i in range(1, len(borders) - 1):
            _fast.add_column_sums(flight.maps, borders[i], borders[i + 1])
        n = len(borders) - 2
        if n and flight.own is not None:
            slot = flight.number % SLOTS
            times = [(0.0 if flight.overlapped else 1e-9 * (started - flight.submitted),
                      1e-9 * cpu) for started, cpu in self._timing[:n, slot]]
            self._measure(borders, list(range(n)) + [len(self._servers)], times + [flight.own])

    def abandon(self) -> None:
        """Wait for the servers' bands in flight, whatever their outcome, and forget them
        (after an error: the model's state is then that of an interrupted step)."""
        if self._flight:
            try:
                self._wait(self._flight[-1].number)
            except BaseException:  # a server's error: raised once, by join
                pass
            self._flight.clear()

    def _measure(self, borders: list[int], threads: list[int],
                 times: list[tuple[float, float]]) -> None:
        """Update the estimates of the threads of the bands from their (other work, band)
        seconds of one frame (band: processor time; an empty band leaves its thread's cost as
        it was), then the borders: rows_i = (finish - other_i) / cost_i, summing to the height,
        with the servers' other work counted ``_MARGIN`` longer. The calling thread (the last)
        gets no band when its other work ends after the servers alone would finish the frame."""
        a = self._SMOOTHING
        cost, other = self._cost, self._other
        for i, (k, (busy, band)) in enumerate(zip(threads, times)):
            if borders[i + 1] > borders[i]:
                c = band / (borders[i + 1] - borders[i])
                cost[k] = c if cost[k] == 0 else (1 - a) * cost[k] + a * c
            other[k] = (1 - a) * other[k] + a * max(busy, 0.0)
        if not all(cost[k] > 0 for k in threads):
            return
        height = borders[-1]
        ahead = [other[k] + (self._MARGIN if k < len(self._servers) else 0.0) for k in threads]
        speed = [1.0 / cost[k] for k in threads]

        def finish(n: int) -> float:  # when the first n threads would be done together
            return (height + sum(o * v for o, v in zip(ahead[:n], speed[:n]))) / sum(speed[:n])

        servers = len(threads) - 1
        banded = servers if finish(servers) <= ahead[-1] else servers + 1
        done = finish(banded)
        rows = [max((done - o) * v, self._min_rows) for o, v in zip(ahead[:banded],
                                                                   speed[:banded])]
        scale, end, new = height / sum(rows), 0.0, [0]
        for i in range(banded - 1):  # every band at least min_rows high
            end += rows[i] * scale
            new.append(int(min(max(round(end), new[-1] + self._min_rows),
                               height - (banded - 1 - i) * self._min_rows)))
        self._borders = new + [height] * (len(threads) + 1 - len(new))
