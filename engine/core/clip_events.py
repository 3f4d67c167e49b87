"""Which of a clip's events a frame's playback passed (``components.model.AnimationEvents``,
fired by the models stage: ``systems/model_system.py``).

Playback runs a clip's time from ``before`` by ``step`` seconds (the frame's time x its speed:
negative plays it backwards).  Laid out as one unwrapped line (a loop's second pass is the
clip's times plus its duration, a third plus twice), an event at time t fires once for each
of its places t + k duration the step passes: forwards those in [before, before + step),
backwards those in (before + step, before], each in the order the playback meets them.  So an
event at 0 fires as a loop starts and each time it comes round, and a loop that wraps three
times in a long frame fires its events three times.  A clip that does not loop stops at its
end (or its start, backwards): an event right there fires on the frame that arrives, once.
"""
from __future__ import annotations

import math
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
    total = 0
    if step > 0.0:
        first, last = math.floor(before / duration), math.floor((before + step) / duration)
        for k in range(first, last + 1):
            for t, n in events:
                at = t + k * duration
                if before <= at < before + step:
                    total += 1
                    if len(fired) < MAX_EVENTS_A_FRAME:
                        fired.append((t, n))
            if total >= MAX_EVENTS_A_FRAME and k < last:  # (the rest only counted)
                total += _count_passes(events, before, step, duration, k + 1, last)
                break
    else:
        first, last = math.floor(before / duration), math.floor((before + step) / duration)
        for k in range(first, last - 1, -1):
            for t, n in reversed(events):
                at = t + k * duration
                if before + step < at <= before:
                    total += 1
                    if len(fired) < MAX_EVENTS_A_FRAME:
                        fired.append((t, n))
            if total >= MAX_EVENTS_A_FRAME and k > last:
                total += _count_passes(events, before + step, -step, duration, last, k - 1, upper=True)
                break
    return fired, total - len(fired)


def _count_passes(events: Sequence[tuple[float, str]], low: float, length: float, duration: float, first: int,
                  last: int, upper: bool = False) -> int:
    """How many event places t + k duration, k in [first, last], lie in [low, low + length)
    (``upper``: in (low, low + length]), counted in closed form (no loop over k)."""
    count = 0
    for t, _ in events:
        if upper:  # k with low < t + k d <= low + length
            lo_k, hi_k = math.floor((low - t) / duration) + 1, math.floor((low + length - t) / duration)
        else:      # k with low <= t + k d < low + length
            lo_k, hi_k = math.ceil((low - t) / duration), math.ceil((low + length - t) / duration) - 1
        count += max(0, min(hi_k, last) - max(lo_k, first) + 1)
    return count


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
