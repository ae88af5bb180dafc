"""Starting, attaching to and restarting sims."""
