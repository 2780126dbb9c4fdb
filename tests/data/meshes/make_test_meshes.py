"""Writes the small hand-made test meshes (run from this directory).

cube_ascii.ply, cube_le.ply and cube_be.ply hold the same mesh: a unit cube scaled by 0.5 and
moved by -1.25 (dyadic, exact in any float type), 6 quad faces, one extra unreferenced vertex
(index 8), per-vertex colours, and extra elements and properties (lists too) that a reader must
skip. tetra_ascii.stl is a tetrahedron whose corners repeat with -0.0 and 0.0 spellings.
"""
import struct

CORNERS = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1), (3, 3, 3)]
POS = [tuple(c * 0.5 - 1.25 for c in v) for v in CORNERS]
QUADS = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
RGBA = [(i * 30, 255 - i * 20, 7 * i, 255 if i % 2 == 0 else 128) for i in range(len(POS))]

with open("cube_ascii.ply", "w", newline="\n") as f:
    f.write("ply\nformat ascii 1.0\ncomment hand-made test cube\nobj_info made by make_test_meshes.py\n")
    f.write(f"element vertex {len(POS)}\nproperty float x\nproperty float y\nproperty float z\n")
    f.write("property float confidence\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n")
    f.write("element material 2\nproperty list uchar float values\nproperty int id\n")
    f.write(f"element face {len(QUADS)}\nproperty uchar flags\nproperty list uchar int vertex_indices\nproperty float quality\n")
    f.write("end_header\n")
    for p, c in zip(POS, RGBA):
        f.write(f"{p[0]} {p[1]} {p[2]} 0.5 {c[0]} {c[1]} {c[2]} {c[3]}\n")
    f.write("3 0.1 0.2 0.3 7\n0 8\n")
    for q in QUADS:
        f.write(f"1 4 {' '.join(map(str, q))} 0.25\n")

# Little-endian: CRLF header lines, the float32 / uint8 / uint32 aliases, a list of varying
# length before the coordinates, a list after the indices, and an element after the faces.
with open("cube_le.ply", "wb") as f:
    f.write(b"ply\r\nformat binary_little_endian 1.0\r\n")
    f.write(f"element vertex {len(POS)}\r\n".encode())
    f.write(b"property list uint8 int16 junk\r\nproperty float32 x\r\nproperty float32 y\r\nproperty float32 z\r\n")
    f.write(b"property uint8 red\r\nproperty uint8 green\r\nproperty uint8 blue\r\nproperty uint8 alpha\r\n")
    f.write(f"element face {len(QUADS)}\r\n".encode())
    f.write(b"property list uint8 uint32 vertex_indices\r\nproperty list uint16 float64 more_junk\r\n")
    f.write(b"element edge 3\r\nproperty int vertex1\r\nproperty int vertex2\r\n")
    f.write(b"end_header\r\n")
    for i, (p, c) in enumerate(zip(POS, RGBA)):
        f.write(struct.pack("<B", i % 3) + struct.pack(f"<{i % 3}h", *range(i % 3)))
        f.write(struct.pack("<3f4B", *p, *c))
    for k, q in enumerate(QUADS):
        f.write(struct.pack("<B4I", 4, *q) + struct.pack(f"<H{k}d", k, *([1.5] * k)))
    for e in range(3):
        f.write(struct.pack("<2i", e, e + 1))

# Big-endian: double coordinates, float colours, signed char list counts, ushort indices.
with open("cube_be.ply", "wb") as f:
    f.write(b"ply\nformat binary_big_endian 1.0\n")
    f.write(f"element vertex {len(POS)}\n".encode())
    f.write(b"property double x\nproperty double y\nproperty double z\n")
    f.write(b"property float red\nproperty float green\nproperty float blue\nproperty float alpha\n")
    f.write(b"property uint tag\n")
    f.write(f"element face {len(QUADS)}\n".encode())
    f.write(b"property list char float texcoord\nproperty list char ushort vertex_index\n")
    f.write(b"end_header\n")
    for i, (p, c) in enumerate(zip(POS, RGBA)):
        f.write(struct.pack(">3d4fI", *p, *(x / 255 for x in c), 0xDEADBEEF))
    for q in QUADS:
        f.write(struct.pack(">b8f", 8, *([0.5] * 8)) + struct.pack(">b4H", 4, *q))

TETRA = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)]
FACETS = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
def spell(x, k):
    # The origin is written as -0 in some corners; it must weld with 0.
    return "-0.0" if x == 0.0 and k % 2 else f"{x:e}"
with open("tetra_ascii.stl", "w", newline="\r\n") as f:
    f.write("solid tetra\n")
    for k, t in enumerate(FACETS):
        f.write("  facet normal 0 0 0\n    outer loop\n")
        for v in t:
            f.write("      vertex " + " ".join(spell(x, k) for x in TETRA[v]) + "\n")
        f.write("    endloop\n  endfacet\n")
    f.write("endsolid tetra\n")
