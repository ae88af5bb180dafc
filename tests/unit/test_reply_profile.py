"""The benchmark of the sim's reply to a step that starts episodes
(``bench --batched --profile``): both encodings are timed on the same step
and give the same bytes (the harness refuses to time replies that differ)."""

from __future__ import annotations

from remoteenv.benchmarks.harness.reply_profile import CASES, reply_profile


def test_reply_profile_times_both_encodings_of_each_case() -> None:
    result = reply_profile(4, blocks=1, per_block=1)
    assert set(result) == set(CASES)
    for per_world, arrays in result.values():
        assert per_world > 0 and arrays > 0
