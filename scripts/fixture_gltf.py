"""What the fixture scripts share (scripts/make_*_fixture.py): PNG files and
a glTF mesh's buffer, written with the standard library only, so that each
fixture's origin is a script anyone can read and rerun."""
import base64
import struct
import zlib


def png(width, height, channels, rows, srgb=False):
    """An 8-bit grey (channels 1) or RGB (channels 3) PNG of `rows`, each a
    flat list of width * channels values, the top row first. srgb: mark the
    texels sRGB-encoded (an sRGB chunk, rendering intent 0), as glTF says a
    base colour texture is; a mask's values are stored as they are."""
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    raw = b"".join(b"\x00" + bytes(row) for row in rows)
    colour_type = {1: 0, 3: 2}[channels]
    header = struct.pack(">IIBBBBB", width, height, 8, colour_type, 0, 0, 0)  # 8 bits, no interlace
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + (chunk(b"sRGB", b"\x00") if srgb else b"") +
            chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def wall_quad_buffer(width, height, centre_y, z):
    """quad_buffer of a width x height rectangle in the plane z, centred on
    x = 0 at height centre_y, facing +z (counter-clockwise seen from there),
    u along +x and v down from its top edge (glTF's v = 0 is an image's top
    row)."""
    x0, x1 = -width / 2, width / 2
    y0, y1 = centre_y - height / 2, centre_y + height / 2
    positions = [(x0, y1, z), (x1, y1, z), (x1, y0, z), (x0, y0, z)]
    return quad_buffer(positions, [(0, 0), (1, 0), (1, 1), (0, 1)], [0, 2, 1, 0, 3, 2])


def quad_buffer(positions, uvs, indices):
    """The glTF fields of a four-corner mesh with TEXCOORD_0 and 16-bit
    indices in one embedded buffer: accessor 0 POSITION, 1 TEXCOORD_0,
    2 indices."""
    data = b"".join(struct.pack("<3f", *p) for p in positions)
    data += b"".join(struct.pack("<2f", *uv) for uv in uvs)
    data += struct.pack("<%dH" % len(indices), *indices)
    low = [min(p[i] for p in positions) for i in range(3)]
    high = [max(p[i] for p in positions) for i in range(3)]
    return {
        "buffers": [{"byteLength": len(data),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(data).decode()}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 12 * len(positions)},
                        {"buffer": 0, "byteOffset": 12 * len(positions), "byteLength": 8 * len(uvs)},
                        {"buffer": 0, "byteOffset": 12 * len(positions) + 8 * len(uvs),
                         "byteLength": 2 * len(indices)}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": len(positions), "type": "VEC3", "min": low, "max": high},
            {"bufferView": 1, "componentType": 5126, "count": len(uvs), "type": "VEC2"},
            {"bufferView": 2, "componentType": 5123, "count": len(indices), "type": "SCALAR"}],
    }
