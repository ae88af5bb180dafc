"""How the worlds advance: lock-step, real time, and batched physics. Runs in the sim process."""
