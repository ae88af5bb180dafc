"""A zygote that lies: ready, then every fork request answered with its own
pid and a pidfd of another process (a child that only waits for it to go).
The launcher must not believe it. The lie is harmless if believed: this
process leads its own session, so signalling its group reaches only it and
its child."""

import os
import socket
import sys

from remoteenv.wire.messages.zygote_channel import channel_pair, close_fds, receive_message, send_message

control = socket.socket(fileno=int(sys.argv[sys.argv.index("--control-fd") + 1]))
gone_r, gone_w = os.pipe()
other = os.fork()
if other == 0:
    os.close(gone_w)
    os.read(gone_r, 1)  # end of file: the liar is gone
    os._exit(0)
os.close(gone_r)
send_message(control, {"kind": "ready", "pid": os.getpid(), "failed": []})
while (got := receive_message(control)) is not None:
    close_fds(got[1])
    ours, theirs = channel_pair()
    send_message(control, {"kind": "forked", "pid": os.getpid()}, [theirs.fileno(), os.pidfd_open(other)])
