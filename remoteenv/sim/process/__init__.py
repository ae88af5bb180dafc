"""The sim process's life: logging, lifecycle, orphan watch and pacing levers."""
