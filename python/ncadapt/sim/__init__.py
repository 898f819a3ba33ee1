"""Virtual machining testbeds: they cut a part with a known error, measure it with noise and
re-cut it with the corrected program. Every simulation is seeded."""
