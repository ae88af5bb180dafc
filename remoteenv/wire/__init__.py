"""What both processes share: the wire spec and codec (:mod:`.protocol`), spaces,
batch encodings, action checks, addresses, CURVE keys and running statistics.

Imports nothing from :mod:`remoteenv.sim` or :mod:`remoteenv.agent`.
"""
