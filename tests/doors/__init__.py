"""Doors as semi-static objects: observation, labels, streams, door-aware navigation."""
