"""Delay specs, their file form, and the delay line that applies them. Both processes use it."""
