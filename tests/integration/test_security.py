"""Security: CURVE keys decide who may drive a sim; nothing on the wire runs code;
binding beyond loopback is refused unless asked for, and then needs keys.

No traffic goes beyond loopback here: CURVE is switched on explicitly on
tcp://127.0.0.1, and the non-loopback cases are refused before any bind.
"""

from __future__ import annotations

import os
import pickle
import stat

import msgpack
import numpy as np
import pytest
import zmq

from remoteenv import Launcher, OpenAIRemoteEnv, protocol, scene_path
from remoteenv.scenes.cartpole.cartpole_scene import CartPoleEnv
from remoteenv.sim.serving.sim_server import RemoteControlledAgent
from remoteenv.wire.files import keys

# How long a rejected client waits for an answer that must never come.
SILENCE_MS = 1500


@pytest.fixture(scope="module")
def curve_env():
    env = OpenAIRemoteEnv(scene_path("cartpole"), transport="tcp", curve=True, startup_timeout=120.0)
    yield env
    env.close()


def _handshake_frame() -> bytes:
    return protocol.pack({"seq": 1, "cmd": "handshake", "protocol": protocol.PROTOCOL_VERSION})


def _ask(endpoint: str, *, server_key: bytes | None = None, client: keys.KeyPair | None = None) -> bytes | None:
    """Send a handshake from a fresh DEALER; the reply frame, or None if none came."""
    sock = zmq.Context.instance().socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 0)
    try:
        if server_key is not None:
            client = client or keys.generate_keypair()
            sock.curve_serverkey = server_key
            sock.curve_publickey = client.public
            sock.curve_secretkey = client.secret
        sock.connect(endpoint)
        sock.send(_handshake_frame())
        return sock.recv() if sock.poll(SILENCE_MS) else None
    finally:
        sock.close(linger=0)


def test_key_holder_drives_a_curve_sim(curve_env):
    sim = curve_env.launcher.sims[0]
    assert sim.endpoint.startswith("tcp://127.0.0.1:") and sim.curve_server_key is not None
    obs, _ = curve_env.reset(seed=0)
    assert curve_env.step(1)[1] == 1.0 and obs.shape == (4,)
    client = curve_env.launcher.curve_client_keypair
    reply = protocol.unpack(_ask(sim.endpoint, server_key=sim.curve_server_key, client=client))
    assert reply["ok"] and reply["env_id"] == "remoteenv/CartPole-v0"


def test_client_without_keys_gets_nothing(curve_env):
    assert _ask(curve_env.launcher.sims[0].endpoint) is None
    curve_env.reset(seed=0)  # this test may run alone (-k, or on its own xdist worker)
    curve_env.step(0)  # the sim still serves its agent


def test_client_with_server_key_but_unlisted_client_key_gets_nothing(curve_env):
    sim = curve_env.launcher.sims[0]
    assert _ask(sim.endpoint, server_key=sim.curve_server_key, client=keys.generate_keypair()) is None


def test_client_with_wrong_server_key_gets_nothing(curve_env):
    sim = curve_env.launcher.sims[0]
    wrong = keys.generate_keypair().public
    assert _ask(sim.endpoint, server_key=wrong, client=curve_env.launcher.curve_client_keypair) is None


def test_secret_key_files_are_private(curve_env):
    workdir = curve_env.launcher.workdir
    assert stat.S_IMODE(os.stat(workdir).st_mode) == 0o700
    secret = os.path.join(workdir, "sim-0.curve_secret")
    assert stat.S_IMODE(os.stat(secret).st_mode) == 0o600
    assert keys.public_from_secret(keys.read_key(secret)) == curve_env.launcher.sims[0].curve_server_key


def test_loopback_without_curve_is_plain_by_default():
    with Launcher(scene_path("cartpole"), transport="tcp", startup_timeout=120.0) as launcher:
        assert launcher.curve_client_keypair is None and launcher.sims[0].curve_server_key is None


def test_binding_beyond_loopback_is_refused_without_keys():
    env = CartPoleEnv()
    with pytest.raises(ValueError, match="not ipc:// or loopback"):
        RemoteControlledAgent([env], "tcp://0.0.0.0:*")
    with pytest.raises(ValueError, match="requires CURVE"):
        RemoteControlledAgent([env], "tcp://0.0.0.0:*", allow_remote=True)
    with pytest.raises(ValueError, match="requires CURVE"):
        Launcher(scene_path("cartpole"), bind_host="0.0.0.0", curve=False)


def test_pickles_and_foreign_extensions_are_never_loaded(tmp_path):
    marker = tmp_path / "ran"

    class Exploit:
        def __reduce__(self):
            return (open, (str(marker), "w"))

    with pytest.raises(protocol.ProtocolError):
        protocol.unpack(pickle.dumps(Exploit()))
    smuggled = msgpack.packb({"seq": 1, "cmd": "step", "action": msgpack.ExtType(2, pickle.dumps(Exploit()))})
    with pytest.raises(protocol.ProtocolError, match="extension type 2"):
        protocol.unpack(smuggled)
    payload = pickle.dumps(Exploit())
    # An array header (see protocol.py) claiming object dtype, with a pickle as its data.
    obj_array = bytes([2]) + b"|O" + bytes([1]) + len(payload).to_bytes(8, "little") + payload
    with pytest.raises(protocol.ProtocolError, match="not allowed"):
        protocol.unpack(msgpack.packb(msgpack.ExtType(1, obj_array)))
    assert not marker.exists()
    # Arrays come back as fresh, writable memory.
    arr = protocol.unpack(protocol.pack(np.arange(3.0)))
    assert arr.flags.writeable and arr.flags.owndata


def test_key_files_round_trip_and_are_checked(tmp_path):
    public_path, secret_path = keys.save_keypair(tmp_path, "server")
    assert stat.S_IMODE(os.stat(secret_path).st_mode) == 0o600
    pair = keys.load_keypair(secret_path)
    assert keys.read_key(public_path) == pair.public
    assert "secret" not in repr(pair).replace("secret=<hidden>", "")
    with pytest.raises(FileExistsError):
        keys.save_keypair(tmp_path, "server")
    bad = tmp_path / "bad.key"
    bad.write_text("not-a-key\n")
    with pytest.raises(ValueError, match="40 characters"):
        keys.read_key(bad)
