"""The scene's contract: the env a scene subclasses, its checks and its viewer. Runs in the sim process."""
