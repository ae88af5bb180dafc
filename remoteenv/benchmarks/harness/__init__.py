"""The benchmarks' parts (agent side): anchors, CPU hogs, contenders in this process, floors, stage profile, timing and report."""
