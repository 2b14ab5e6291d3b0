"""The worm and its magnets as data: parameters, materials, gait paths, the crease pattern, the magnet API."""
