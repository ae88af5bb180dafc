"""split_reply: one step_batch reply as two, finals and their types following their worlds."""

from __future__ import annotations

import numpy as np

from remoteenv.agent.vector.vector_async import split_reply


def test_split_reply_keeps_each_world_with_its_values_and_final() -> None:
    reply = {
        "obs": np.arange(8.0).reshape(4, 2),
        "reward": [0.0, 1.0, 2.0, 3.0],
        "terminated": [False, True, False, True],
        "truncated": [False] * 4,
        "info": {"columns": {"d": [np.array([5, 6, 7, 8], np.float32), [True, False, True, True]]}},
        "final": [[1, "o1", {"x": 1}], [3, "o3", {"x": 3}]],
        "final_types": [None, {"x": "<f4"}],
    }
    head, tail = split_reply(reply, 2)
    np.testing.assert_array_equal(head["obs"], [[0, 1], [2, 3]])
    assert tail["reward"] == [2.0, 3.0] and tail["terminated"] == [False, True]
    values, present = tail["info"]["columns"]["d"]
    assert values.dtype == np.float32 and values.tolist() == [7, 8] and present == [True, True]
    assert head["final"] == [[1, "o1", {"x": 1}]] and head["final_types"] == [None]
    assert tail["final"] == [[1, "o3", {"x": 3}]] and tail["final_types"] == [{"x": "<f4"}]


def test_split_reply_of_map_infos_without_types() -> None:
    reply = {
        "obs": [1, 2, 3],
        "reward": [0.0] * 3,
        "terminated": [False] * 3,
        "truncated": [False] * 3,
        "info": {"maps": [{"a": 1}, {}, {"b": "s"}]},
        "final": [],
    }
    head, tail = split_reply(reply, 1)
    assert head["info"] == {"maps": [{"a": 1}]} and tail["info"] == {"maps": [{}, {"b": "s"}]}
    assert head["obs"] == [1] and tail["obs"] == [2, 3]
    assert "final_types" not in head and "final_types" not in tail
