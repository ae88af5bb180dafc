"""One env's session with its sims: calls, attributes, pausing, pickling. Runs in the agent process."""
