"""Push events of a streaming MEASURE: phases, sample batches and the running answer, best effort.

A MEASURE with ``stream = true`` gets, before its reply, EVENT frames addressed with its request id
(:data:`edge.protocol.commands.EVENTS`). They are produced on the measurement's own thread by three
taps that never change what the sequence sees:

* :class:`TappedSensors` wraps the sensors: each reading is passed on unchanged and also appended
  to the current sample batch;
* :class:`TappedDecision` wraps the running decision: each answer is passed on unchanged and also
  offered to the stream;
* the daemon's phase callback calls :meth:`EventStream.phase`.

Bounds: a batch goes out when it holds :data:`~edge.protocol.commands.MAX_EVENT_SAMPLES` samples or
:data:`EVENT_PERIOD_s` of board time has passed since the last one; the running answer at most
once per :data:`EVENT_PERIOD_s` (the latest one is sent before each phase event). So a touch sends
at most about ``2 / EVENT_PERIOD_s`` frames per second of board time plus its phases, whatever its
sample rate. Sending only queues the frame (:meth:`edge.protocol.endpoint.SerialEndpoint.send_event`,
which never blocks and drops events past its own byte bound); any failure inside a tap is logged
and ends the stream, never the touch: the heater's safety paths do not pass through this module.
"""

from __future__ import annotations

import logging
import math
import threading
from typing import Any, Callable

from edge.protocol.commands import MAX_EVENT_SAMPLES, EventKind

__all__ = ["EVENT_PERIOD_s", "EventStream", "TappedSensors", "TappedDecision"]

log = logging.getLogger("thermotouch.edge")

#: Least board time between two sample batches, and between two running answers, s.
EVENT_PERIOD_s = 0.1

#: ``send(body, final=False) -> bool``: queue one event body (False: dropped); ``final``: the last one.
Send = Callable[..., bool]


def _num(x: float, digits: int) -> float | None:
    x = float(x)
    return round(x, digits) if math.isfinite(x) else None


class EventStream:
    """The events of one streaming measurement.

    Parameters
    ----------
    send : callable
        ``send(body, final=False) -> bool`` queues one event body (e.g. ``endpoint.send_event`` bound to
        the request id); ``final`` marks ``done``, which the link queues under the replies' bound.
    clock : callable
        The board clock (``monotonic``), the time base of every ``t_s``.
    armed : bool
        Whether the touch is armed (its baseline phase is then called ``armed``, and ``contact``
        precedes ``heating``).
    dropped : callable, optional
        ``() -> int``: the link's count of dropped events (reported with ``done``).
    """

    def __init__(self, send: Send, clock: Callable[[], float], *, armed: bool = False,
                 dropped: Callable[[], int] | None = None) -> None:
        self._send = send
        self._clock = clock
        self.armed = bool(armed)
        self._dropped = dropped
        self._dropped0 = dropped() if dropped is not None else 0
        self.t0 = clock()
        self._lock = threading.Lock()
        self._seq = 0
        self._batch: tuple[list, list, list] = ([], [], [])
        self._batch_t = self.t0
        self._answer: dict | None = None
        self._answer_t = -math.inf
        # Cool-down readings are kept apart from the record's series (edge.measure.sequence): not streamed.
        self._cooling = False
        self.closed = False
        #: Events handed to the link (queued) and refused by it (dropped) during this measurement.
        self.sent = 0
        self.refused = 0

    def _t(self, t_board: float | None = None) -> float:
        return round((self._clock() if t_board is None else t_board) - self.t0, 6)

    def _emit(self, kind: EventKind, t_s: float, final: bool = False, **fields: Any) -> None:
        body = {"kind": str(kind), "seq": self._seq, "t_s": t_s, **fields}
        self._seq += 1
        try:
            ok = self._send(body, final=True) if final else self._send(body)
        except Exception:  # a link that cannot take events ends the stream, not the touch
            log.exception("event stream ended: the link refused an event")
            self.closed = True
            return
        if ok:
            self.sent += 1
        else:
            self.refused += 1

    def _guard(self, fn: Callable[[], None]) -> None:
        if self.closed:
            return
        with self._lock:
            try:
                fn()
            except Exception:
                log.exception("event stream ended by an error; the measurement goes on")
                self.closed = True

    # -- taps ----------------------------------------------------------------------------
    def sample(self, t_board: float, T_C: float, q_W_m2: float) -> None:
        """One reading at board time ``t_board`` (the middle of its read, as the sequence records it).

        Readings of a cool-down are not streamed: the samples are exactly the record's raw series.
        """
        def add() -> None:
            if self._cooling:
                return
            ts, Ts, qs = self._batch
            ts.append(self._t(t_board))
            Ts.append(_num(T_C, 4))
            qs.append(_num(q_W_m2, 3))
            if len(ts) >= MAX_EVENT_SAMPLES or t_board - self._batch_t >= EVENT_PERIOD_s:
                self._flush_samples()
            self._flush_answer(force=False)
        self._guard(add)

    def answer(self, ans: Any) -> None:
        """A running answer (a RunningAnswer, or its dict); sent now if the last one is old enough."""
        def offer() -> None:
            d = ans.to_dict() if hasattr(ans, "to_dict") else dict(ans)
            self._answer = d
            self._flush_answer(force=False)
        self._guard(offer)

    def phase(self, phase: str) -> None:
        """The sequence entered ``phase`` (a :class:`edge.measure.sequence.Phase` word); ``idle`` only flushes."""
        def enter() -> None:
            self._flush_samples()
            self._flush_answer(force=True)
            word = str(phase)
            self._cooling = word == "cooldown"
            if word == "idle":
                return
            if word == "baseline" and self.armed:
                word = "armed"
            t = self._t()
            if word == "heating" and self.armed:
                self._emit(EventKind.PHASE, t, phase="contact")
            self._emit(EventKind.PHASE, t, phase=word)
        self._guard(enter)

    def close(self, measurement_id: int | None, status: str | None) -> None:
        """The last event: ``done`` with the stored record's id (None: not stored) and the event counts."""
        def done() -> None:
            self._flush_samples()
            self._flush_answer(force=True)
            dropped = (self._dropped() - self._dropped0) if self._dropped is not None else self.refused
            self._emit(EventKind.PHASE, self._t(), True, phase="done", measurement_id=measurement_id, status=status,
                       events_sent=self.sent, events_dropped=max(0, int(dropped)))
        self._guard(done)
        self.closed = True

    # -- batching -------------------------------------------------------------------------
    def _flush_samples(self) -> None:
        ts, Ts, qs = self._batch
        if ts:
            self._emit(EventKind.SAMPLES, ts[-1], sample_t_s=ts, T_C=Ts, q_W_m2=qs)
        self._batch = ([], [], [])
        self._batch_t = self._clock()

    def _flush_answer(self, *, force: bool) -> None:
        if self._answer is None:
            return
        now = self._clock()
        if force or now - self._answer_t >= EVENT_PERIOD_s:
            self._emit(EventKind.ANSWER, self._t(now), answer=self._answer)
            self._answer = None
            self._answer_t = now


class TappedSensors:
    """The sensors, unchanged, with each reading also given to an :class:`EventStream`.

    Every attribute but ``read`` is the wrapped sensors' own; a read's exception (a sensor fault)
    propagates exactly as without the tap.
    """

    def __init__(self, sensors: Any, stream: EventStream, clock: Callable[[], float]) -> None:
        self._sensors = sensors
        self._stream = stream
        self._clock = clock

    def read(self) -> Any:
        t0 = self._clock()
        r = self._sensors.read()
        t1 = self._clock()
        try:
            self._stream.sample(0.5 * (t0 + t1), r.T_C, r.q_W_m2)
        except Exception:  # pragma: no cover - sample() guards itself; this is the last line
            log.exception("sample tap failed")
        return r

    def __getattr__(self, name: str) -> Any:
        return getattr(self._sensors, name)


class TappedDecision:
    """A running decision, unchanged, with each new answer also given to an :class:`EventStream`.

    Other attributes (``attach_record`` where the decision has one) are the wrapped decision's, so
    ``hasattr`` answers as it would without the tap.
    """

    def __init__(self, decision: Any, stream: EventStream) -> None:
        self._decision = decision
        self._stream = stream

    def update(self, *args: Any, **kwargs: Any) -> Any:
        ans = self._decision.update(*args, **kwargs)
        if ans is not None:
            try:
                self._stream.answer(ans)
            except Exception:  # pragma: no cover - answer() guards itself
                log.exception("answer tap failed")
        return ans

    def __getattr__(self, name: str) -> Any:
        return getattr(self._decision, name)
