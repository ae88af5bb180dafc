"""Starting, attaching to and restarting sims. Runs in the agent process."""
