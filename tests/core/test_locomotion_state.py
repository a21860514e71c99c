# SPDX-License-Identifier: GPL-3.0-or-later
"""Per-foot state (``core.locomotion.state``) and the step's profiler."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from procloco_addon.core.locomotion.profile import Profiler
from procloco_addon.core.locomotion.state import Phase, phases_of, start_feet


def test_the_four_phases_round_trip_through_their_flags() -> None:
    feet = start_feet(np.zeros((4, 3)), 4)
    swinging = np.array([False, True, True, False])
    forced = np.array([False, False, True, False])
    failed = np.array([False, False, False, True])
    feet.set_flags(swinging, forced, failed)
    assert feet.phase.tolist() == [Phase.PLANTED, Phase.SWING, Phase.FORCED, Phase.STUCK]
    got = feet.flags()
    for a, b in zip(got, (swinging, forced, failed), strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(phases_of(*got), feet.phase)


@pytest.mark.parametrize(
    "flags",
    [f for f in itertools.product([False, True], repeat=3)
     if f not in {(False, False, False), (True, False, False), (True, True, False), (False, False, True)}],
)
def test_flags_that_are_no_phase_are_refused(flags: tuple[bool, bool, bool]) -> None:
    feet = start_feet(np.zeros((1, 3)), 4)
    with pytest.raises(ValueError, match="no phase"):
        feet.set_flags(*(np.array([f]) for f in flags))
    assert feet.phase.tolist() == [Phase.PLANTED]  # nothing changed


def test_the_profiler_books_each_phase_and_the_rest() -> None:
    ticks = iter([0.0, 1.0, 3.0, 4.0, 4.5, 10.0])
    seconds: dict[str, float] = {}
    prof = Profiler(seconds, lambda: next(ticks))
    with prof.phase("maps"):
        pass  # 1.0 -> 3.0
    with prof.phase("ik"):
        pass  # 4.0 -> 4.5
    prof.finish()  # 10.0 since 0.0
    assert seconds == {"maps": 2.0, "ik": 0.5, "rest": 7.5}
