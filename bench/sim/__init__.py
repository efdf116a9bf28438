"""A minimal raycast world simulator: boxes in a room, a pinhole depth camera, a mask detector."""
