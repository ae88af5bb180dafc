"""The vector env's requests, results, layout and autoreset."""
