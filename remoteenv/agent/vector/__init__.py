"""The vector env's requests, results, layout and autoreset. Runs in the agent process."""
