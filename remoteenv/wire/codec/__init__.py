"""How values become bytes, in both processes: arrays, scalars, value counts, frame limits, spaces."""
