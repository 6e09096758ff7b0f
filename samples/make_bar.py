# SPDX-License-Identifier: MIT
"""Writes bar.obj: a closed, outward-facing triangle mesh of a rounded bar, the superellipsoid
|x/15|^4 + |y/5|^4 + |z/5|^4 = 1 (mm), by projecting a latitude-longitude sphere onto it
radially. Its polycube is bar.cubes (three cubes in a row along x). Run: python3 make_bar.py"""
import math

A = (15.0, 5.0, 5.0)  # semi-axes, mm
P = 4.0               # exponent: 2 is an ellipsoid, larger is boxier
N_LAT, N_LON = 24, 48


def on_surface(d):
    t = sum((abs(c) / a) ** P for c, a in zip(d, A)) ** (-1.0 / P)
    return tuple(t * c for c in d)


def main():
    verts = [on_surface((0.0, 0.0, 1.0))]
    for i in range(1, N_LAT):
        theta = math.pi * i / N_LAT
        for j in range(N_LON):
            phi = 2 * math.pi * j / N_LON
            verts.append(on_surface((math.sin(theta) * math.cos(phi),
                                     math.sin(theta) * math.sin(phi), math.cos(theta))))
    verts.append(on_surface((0.0, 0.0, -1.0)))
    ring = lambda i, j: 1 + (i - 1) * N_LON + j % N_LON  # 0-based index, ring i >= 1
    south = len(verts) - 1
    faces = []
    for j in range(N_LON):
        faces.append((0, ring(1, j), ring(1, j + 1)))
        for i in range(1, N_LAT - 1):
            a, b = ring(i, j), ring(i, j + 1)
            c, d = ring(i + 1, j), ring(i + 1, j + 1)
            faces += [(a, c, d), (a, d, b)]
        faces.append((ring(N_LAT - 1, j), south, ring(N_LAT - 1, j + 1)))
    with open("bar.obj", "w") as f:
        f.write("# rounded bar 30 x 10 x 10 mm, written by make_bar.py; polycube: bar.cubes\n")
        for v in verts:
            f.write("v {:.5f} {:.5f} {:.5f}\n".format(*v))
        for t in faces:
            f.write("f {} {} {}\n".format(*(k + 1 for k in t)))


if __name__ == "__main__":
    main()
