#!/usr/bin/env python3
"""Writes cylinder_shell.stl: a hollow cylinder, 30 mm outer diameter, 26 mm inner, 5 mm tall (mm),
as a closed ASCII STL. The G-code test part (see README.md in this folder)."""
import math

SEGMENTS = 96
OUTER, INNER, HEIGHT = 15.0, 13.0, 5.0


def ring(radius, z):
    return [(radius * math.cos(2 * math.pi * k / SEGMENTS), radius * math.sin(2 * math.pi * k / SEGMENTS), z)
            for k in range(SEGMENTS)]


def facet(out, a, b, c):
    ux, uy, uz = (b[i] - a[i] for i in range(3))
    vx, vy, vz = (c[i] - a[i] for i in range(3))
    n = (uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx)
    length = math.sqrt(sum(x * x for x in n)) or 1.0
    out.append("facet normal %g %g %g\n outer loop\n" % tuple(x / length for x in n))
    for p in (a, b, c):
        out.append("  vertex %.6f %.6f %.6f\n" % p)
    out.append(" endloop\nendfacet\n")


out = ["solid cylinder_shell\n"]
ob, ot, ib, it = ring(OUTER, 0), ring(OUTER, HEIGHT), ring(INNER, 0), ring(INNER, HEIGHT)
for k in range(SEGMENTS):
    n = (k + 1) % SEGMENTS
    facet(out, ob[k], ob[n], ot[n]); facet(out, ob[k], ot[n], ot[k])    # outer wall, facing out
    facet(out, ib[n], ib[k], it[k]); facet(out, ib[n], it[k], it[n])    # inner wall, facing in
    facet(out, ot[k], ot[n], it[n]); facet(out, ot[k], it[n], it[k])    # top ring, facing up
    facet(out, ob[n], ob[k], ib[k]); facet(out, ob[n], ib[k], ib[n])    # bottom ring, facing down
out.append("endsolid cylinder_shell\n")
open("cylinder_shell.stl", "w").write("".join(out))
