"""How a sim's worlds run, in both processes: the run options and the real-time regimes."""
