"""Which of a clip's events a frame's playback passed (``components.model.AnimationEvents``,
fired by the models stage: ``systems/model_system.py``).

Playback runs a clip's time from ``before`` by ``step`` seconds (the frame's time x its speed:
negative plays it backwards).  Laid out as one unwrapped line (a loop's second pass is the
clip's times plus its duration, a third plus twice), an event at time t fires once for each
of its places t + k duration the step passes: forwards those in [before, before + step),
backwards those in (before + step, before], each in the order the playback meets them (an
event at the very end of a looping clip, the next pass's start, going forwards as the playback
arrives there), whether or not a frame lands right on a wrap or an event.  So an event at 0
fires as a loop starts and each time it comes round, and a loop that wraps three times in a
long frame fires its events three times.  A clip that does not loop stops at its end (or its
start, backwards): an event right there fires on the frame that arrives, once.
"""
from __future__ import annotations

from collections.abc import Sequence

# A frame at most fires this many of one clip's events (a tiny looping clip stepped a long
# frame would fire thousands: the first are fired, the rest counted as dropped).
MAX_EVENTS_A_FRAME = 256


def passed_events(events: Sequence[tuple[float, str]], before: float, step: float, duration: float,
                  loop: bool) -> tuple[list[tuple[float, str]], int]:
    """The (time, name) of ``events`` (sorted by time) a playback passes from ``before`` by
    ``step`` seconds of a clip ``duration`` long (the module docstring), in the order met,
    and how many past ``MAX_EVENTS_A_FRAME`` were left out."""
    if step == 0.0 or not events:
        return [], 0
    fired: list[tuple[float, str]] = []
    if not loop or duration <= 0.0:
        end = min(max(before + step, 0.0), duration) if duration > 0.0 else before + step
        if step > 0.0:
            arrived = end >= duration and before < duration
            fired = [(t, n) for t, n in events if before <= t < end or (arrived and t == end)]
        else:
            arrived = end <= 0.0 < before
            fired = [(t, n) for t, n in reversed(events) if end < t <= before or (arrived and t == end)]
        return fired[:MAX_EVENTS_A_FRAME], max(len(fired) - MAX_EVENTS_A_FRAME, 0)
    # Where the playback starts and ends as (pass of the loop, time within it), found as the
    # models stage wraps a time (``time % duration``), so a frame ends exactly where the next
    # starts: an event's place is compared there, never as t + k x duration rounded, which
    # can fall just past a frame's end and just before the next frame's start and fire in
    # neither.  An event at the clip's very end (t = duration) is the next pass's start: met
    # going forwards it fires as the playback arrives there (a frame landing right on the
    # wrap fires it then), going backwards as it leaves (with the next pass's events at 0).
    after = before + step
    at_before, at_after = (at if at < duration else 0.0 for at in (before % duration, after % duration))
    # (a tiny time below 0 wraps to the duration itself: the next pass's start)
    pass_before = round((before - at_before) / duration)
    pass_after = round((after - at_after) / duration)
    spans = [_passes(t, at_before, pass_before, at_after, pass_after, step > 0.0, duration) for t, _ in events]
    total = sum(max(0, high - low + 1) for low, high in spans)
    if step > 0.0:
        order, passes = list(zip(events, spans, strict=True)), range(pass_before, pass_after + 1)
    else:
        order, passes = list(zip(events, spans, strict=True))[::-1], range(pass_before, pass_after - 1, -1)
    for k in passes:
        if len(fired) >= min(total, MAX_EVENTS_A_FRAME):
            break
        fired.extend((t, n) for (t, n), (low, high) in order if low <= k <= high)
    fired = fired[:MAX_EVENTS_A_FRAME]
    return fired, total - len(fired)


def _passes(t: float, at_before: float, pass_before: int, at_after: float, pass_after: int, forwards: bool,
            duration: float) -> tuple[int, int]:
    """The passes of the loop (first, last) in which a playback from (``pass_before``,
    ``at_before``) to (``pass_after``, ``at_after``) meets an event at ``t``: forwards those
    from the one it leaves at or after ``t`` to the one it ends before ``t``; backwards from
    the one it ends below ``t`` to the one it leaves at or above ``t``; an event at the end
    (t >= duration, the next pass's start) arrived at forwards, left backwards."""
    if t >= duration:
        return (pass_before, pass_after - 1) if forwards else (pass_after, pass_before - 1)
    if forwards:
        return (pass_before if t >= at_before else pass_before + 1, pass_after if t < at_after else pass_after - 1)
    return (pass_after if t > at_after else pass_after + 1, pass_before if t <= at_before else pass_before - 1)


def events_problem(events: Sequence[tuple[str, float, str]], clips: dict[str, float]) -> str | None:
    """Why ``events`` ((clip, time, name), an ``AnimationEvents``'s) cannot play on a model whose
    clips are ``clips`` (name: duration): an event on a clip it has not, or past its clip's
    end; None when every one can.  The one rule the models stage and a level file's reader check."""
    for clip, time, name in events:
        if clip not in clips:
            names = ", ".join(repr(c) for c in clips) or "none"
            return f"event {name!r} is on clip {clip!r}, which the model has not (its clips: {names})"
        if time > clips[clip] + 1e-6:
            return f"event {name!r} at {time:g} s is past the end of clip {clip!r} ({clips[clip]:g} s long)"
    return None
