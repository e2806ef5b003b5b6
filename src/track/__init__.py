"""Track model: layout, FE bodies, bushings, Craig-Bampton reduction, dynamics, contact, post-processing."""
