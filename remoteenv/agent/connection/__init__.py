"""Connections to a sim: the pipe, ZeroMQ, reply checks and the shared region. Runs in the agent process."""
