"""Loads: each kind (traction, total force, body force, nodal force, pressure, gravity) is a
module and one entry of ``registry.LOADS``, which owns its scene keys and its assembly; the
scene reads a ``[[loads]]`` table through the entry of the key it gives, and ``build`` turns the
scene's loads into named patterns."""
