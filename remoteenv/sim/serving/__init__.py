"""The server loop: commands, attributes and the stepping mode it serves. Runs in the sim process."""
