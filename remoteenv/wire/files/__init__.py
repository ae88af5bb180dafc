"""Files both sides read: launch-info files, CURVE keys, bounded reads."""
