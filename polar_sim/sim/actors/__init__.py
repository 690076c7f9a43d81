"""The bodies that act in the scenes: the wheeled rovers (presets, drive, sensors' mounts) and the
hand that touches and occludes objects on the tabletop."""
