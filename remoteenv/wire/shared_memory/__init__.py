"""The shared region both processes map, its doorbell and the hot wait."""
