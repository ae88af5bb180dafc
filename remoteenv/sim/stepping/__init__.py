"""How the worlds advance: lock-step, real time, and batched physics."""
