"""Frames streamed from publisher sim processes into a torch DataLoader."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

torch = pytest.importorskip("torch")
from torch.utils.data import DataLoader  # noqa: E402

from remoteenv import RemoteEnvError  # noqa: E402
from remoteenv.integrations.frame_dataset import RemoteIterableDataset, launch_publishers  # noqa: E402

W, H = 48, 32


def test_two_publishers_two_workers_every_item_exactly_once():
    items = 12
    with launch_publishers(
        "cartpole", num_instances=2, items_per_instance=items, seed=5, episode_steps=5, width=W, height=H
    ) as pubs:
        dataset = RemoteIterableDataset.from_publishers(pubs)
        assert len(dataset) == 2 * items
        loader = DataLoader(dataset, batch_size=4, num_workers=2)
        seen = []
        for batch in loader:
            assert batch["frame"].dtype == torch.uint8
            assert tuple(batch["frame"].shape[1:]) == (H, W, 3)
            assert batch["labels"]["obs"].shape[1:] == (4,)
            seen += list(
                zip(
                    batch["instance"].tolist(),
                    batch["index"].tolist(),
                    batch["episode"].tolist(),
                    batch["step"].tolist(),
                )
            )
            assert batch["frame"].float().std() > 0  # a rendered picture, not a blank buffer
    assert len(seen) == 2 * items
    assert sorted((i, k) for i, k, _, _ in seen) == [(i, k) for i in range(2) for k in range(items)]
    # Episodes of 5 ticks: item k is tick k % 5 of episode k // 5 (cartpole does not fall in 5 ticks).
    assert all(step == k % 5 and ep == k // 5 for _, k, ep, step in seen)


def test_labels_match_the_frame_state_and_seed_reproduces_the_stream():
    def stream(seed):
        with launch_publishers("cartpole", num_instances=1, items_per_instance=6, seed=seed, width=W, height=H) as pubs:
            return list(RemoteIterableDataset.from_publishers(pubs))

    a, b, c = stream(1), stream(1), stream(2)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x["labels"]["obs"], y["labels"]["obs"])
        np.testing.assert_array_equal(x["frame"], y["frame"])
    assert not np.array_equal(a[0]["labels"]["obs"], c[0]["labels"]["obs"])
    for item in a:
        obs, qpos = item["labels"]["obs"], item["labels"]["qpos"]
        assert obs[0] == pytest.approx(qpos[0], abs=1e-6) and obs[2] == pytest.approx(qpos[1], abs=1e-6)


def test_more_workers_than_publishers_still_reads_each_item_once():
    with launch_publishers("cartpole", num_instances=1, items_per_instance=5, seed=0, width=W, height=H) as pubs:
        loader = DataLoader(RemoteIterableDataset.from_publishers(pubs), batch_size=None, num_workers=2)
        indices = [item["index"] for item in loader]
    assert sorted(indices) == list(range(5))


def test_vanished_publisher_raises_clear_error():
    with launch_publishers("cartpole", num_instances=1, seed=0, width=W, height=H) as pubs:
        dataset = RemoteIterableDataset.from_publishers(pubs)
        loader = DataLoader(dataset, batch_size=None, num_workers=1)
        it = iter(loader)
        first = next(it)
        assert first["index"] == 0
        os.kill(pubs.pids[0], signal.SIGKILL)
        with pytest.raises(Exception) as err:
            for _ in range(1000):  # endless stream: only the death can end this loop
                next(it)
        text = str(err.value)
        assert "frame publisher 0" in text and "vanished" in text and str(pubs.pids[0]) in text
        del it


def test_in_process_vanished_publisher_raises_remote_env_error():
    with launch_publishers("reacher", num_instances=1, seed=0, width=W, height=W) as pubs:
        it = iter(RemoteIterableDataset.from_publishers(pubs))
        assert next(it)["frame"].shape == (W, W, 3)
        os.kill(pubs.pids[0], signal.SIGKILL)
        with pytest.raises(RemoteEnvError, match="vanished") as err:
            for _ in range(1000):
                next(it)
        assert err.value.kind == "died"


def _indices(loader) -> dict[int, list[int]]:
    """Each publisher's item indices, in the order one pass over ``loader`` yields them."""
    out: dict[int, list[int]] = {}
    for batch in loader:
        for i, k in zip(batch["instance"].tolist(), batch["index"].tolist()):
            out.setdefault(i, []).append(k)
    return out


@pytest.mark.parametrize("workers", [0, 2])
def test_every_epoch_reads_the_next_items_of_each_publisher(workers):
    items = 5
    with launch_publishers("cartpole", num_instances=2, items_per_instance=items, seed=1, width=W, height=H) as pubs:
        # timeout: a second pass that got nothing (the old behaviour) fails fast.
        dataset = RemoteIterableDataset.from_publishers(pubs, timeout=10.0)
        loader = DataLoader(dataset, batch_size=3, num_workers=workers)
        for epoch in range(3):
            seen = _indices(loader)
            assert seen == {i: list(range(epoch * items, (epoch + 1) * items)) for i in range(2)}, epoch


def test_a_pass_left_early_drops_at_most_the_window():
    from remoteenv.wire.messages.stream_credit import WINDOW

    with launch_publishers("cartpole", num_instances=1, seed=0, width=W, height=H) as pubs:
        dataset = RemoteIterableDataset(pubs.endpoints, items_per_publisher=4, pids=pubs.pids, timeout=10.0)
        for item in dataset:
            if item["index"] == 1:
                break  # two read, the rest of what was asked for is dropped
        nxt = [item["index"] for item in dataset]
        assert len(nxt) == 4 and nxt == list(range(nxt[0], nxt[0] + 4))
        assert 2 <= nxt[0] <= 2 + WINDOW


def test_two_readers_of_one_publisher_are_told_apart():
    with launch_publishers("cartpole", num_instances=1, seed=0, width=W, height=H) as pubs:
        first = iter(RemoteIterableDataset(pubs.endpoints, pids=pubs.pids, timeout=10.0))
        second = iter(RemoteIterableDataset(pubs.endpoints, pids=pubs.pids, timeout=10.0))
        with pytest.raises(RemoteEnvError, match="another reader is reading it too"):
            for _ in range(100):
                next(first)
                next(second)
        first.close()
        second.close()


def _reference_frame(qpos, qvel, quality: bool) -> np.ndarray:
    """CartPole's side camera rendered here from a state: cheaply (no multisampling,
    no shadows) or at the MJCF's quality."""
    import mujoco

    import remoteenv

    model = mujoco.MjModel.from_xml_path(
        os.path.join(os.path.dirname(remoteenv.scene_path("cartpole")), "cartpole.xml")
    )
    if not quality:
        model.vis.quality.offsamples, model.vis.quality.shadowsize = 0, 0
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = qpos, qvel
    mujoco.mj_forward(model, data)
    with mujoco.Renderer(model, height=H, width=W) as renderer:
        renderer.update_scene(data, camera="side")
        return renderer.render().copy()


@pytest.mark.parametrize("quality", [False, True])
def test_frames_are_cheap_by_default_and_at_the_mjcf_quality_when_asked(quality):
    """Streamed frames render without multisampling and shadows unless quality=True
    (at 64x64 about 50x cheaper under software OpenGL): each episode's first frame
    is bit for bit MuJoCo's own render of its state at that quality."""
    kwargs = {} if not quality else {"quality": True}
    with launch_publishers(
        "cartpole", num_instances=1, items_per_instance=4, seed=2, episode_steps=2, width=W, height=H, **kwargs
    ) as pubs:
        items = list(RemoteIterableDataset.from_publishers(pubs))
    firsts = [item for item in items if item["step"] == 0]  # right after a reset: the state is the labels'
    assert len(firsts) == 2
    for item in firsts:
        labels = item["labels"]
        np.testing.assert_array_equal(item["frame"], _reference_frame(labels["qpos"], labels["qvel"], quality))
        other = _reference_frame(labels["qpos"], labels["qvel"], not quality)
        assert not np.array_equal(item["frame"], other)  # the two qualities differ visibly
