"""How requests reach the sim: channels, peers, drivers, limits, the shared region. Runs in the sim process."""
