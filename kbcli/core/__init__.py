"""Pure numeric core: numpy arrays in, arrays out; no I/O, no CLI, no pymunk."""
