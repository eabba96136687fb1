#!/usr/bin/env python3
"""Writes the small seed corpus under fuzz/corpus/<target>/ (committed; rerun to regenerate).

frame_image's seeds are not written here (Python has no JPEG encoder): they were made with
  ffmpeg -f lavfi -i testsrc=size=24x16 -frames:v 1 -q:v 5 baseline.jpg  (also gray.jpg, rgb.png)

Multi-file targets take their files joined as scene::fuzz_entry::split_parts reads them: every
file but the last is prefixed by its length as a little-endian u16.
"""
import io
import json
import os
import struct
import tarfile
import gzip
import zipfile
import zlib

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "corpus")


def joined(*parts):
    out = b""
    for part in parts[:-1]:
        out += struct.pack("<H", len(part)) + part
    return out + parts[-1]


def write(target, name, data):
    folder = os.path.join(ROOT, target)
    os.makedirs(folder, exist_ok=True)
    with open(os.path.join(folder, name), "wb") as f:
        f.write(data)


def png(width, height, bit_depth, color_type, raw_rows):
    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)
    ihdr = struct.pack(">IIBBBBB", width, height, bit_depth, color_type, 0, 0, 0)
    data = b"".join(b"\x00" + row for row in raw_rows)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(data)) + chunk(b"IEND", b"")


def colmap():
    cameras = struct.pack("<Q", 1) + struct.pack("<IiQQ", 1, 1, 4, 3) + struct.pack("<4d", 3.0, 3.0, 2.0, 1.5)
    images = struct.pack("<Q", 1) + struct.pack("<I4d3dI", 1, 1, 0, 0, 0, 0, 0, 4, 1) + b"a.png\0"
    images += struct.pack("<Q", 1) + struct.pack("<2dq", 1.0, 1.0, 1)
    points = struct.pack("<Q", 1) + struct.pack("<Q3d", 1, 0.1, 0.2, 0.3) + bytes([200, 100, 50])
    points += struct.pack("<dQ", 0.5, 1) + struct.pack("<II", 1, 0)
    write("colmap_binary", "pinhole", joined(cameras, images, points))
    opencv = struct.pack("<Q", 1) + struct.pack("<IiQQ", 1, 4, 4, 3) + struct.pack("<8d", 3, 3, 2, 1.5, 0.01, 0, 0, 0)
    write("colmap_binary", "opencv_no_points", joined(opencv, images, struct.pack("<Q", 0)))
    cameras_txt = b"# Camera list\n1 PINHOLE 4 3 3 3 2 1.5\n2 SIMPLE_RADIAL 4 3 3 2 1.5 0.01\n"
    images_txt = b"# Image list\n1 1 0 0 0 0 0 4 1 a.png\n1 1 1\n2 0.7071 0 0.7071 0 1 0 4 2 b.png\n\n"
    points_txt = b"# 3D point list\n1 0.1 0.2 0.3 200 100 50 0.5 1 0 2 0\n"
    write("colmap_text", "two_images", joined(cameras_txt, images_txt, points_txt))


def ply():
    ascii_ply = (b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                 b"property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
                 b"end_header\n0 0 0 255 0 0\n1 2 3 0 255 0\n")
    write("ply", "ascii", ascii_ply)
    header = (b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty double x\n"
              b"property double y\nproperty double z\nend_header\n")
    write("ply", "binary_le", header + struct.pack("<6d", 0, 0, 0, 1, 2, 3))


def transforms():
    pose = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]
    nerfstudio = {"camera_model": "OPENCV", "fl_x": 3, "fl_y": 3, "cx": 2, "cy": 1.5, "w": 4, "h": 3,
                  "k1": 0.01, "frames": [{"file_path": "images/a.png", "transform_matrix": pose}]}
    write("transforms_json", "nerfstudio", json.dumps(nerfstudio).encode())
    blender = {"camera_angle_x": 0.69, "frames": [{"file_path": "./train/r_0", "time": 0.5,
                                                   "transform_matrix": pose}]}
    write("transforms_json", "blender", json.dumps(blender).encode())


def nerfies():
    dataset = json.dumps({"ids": ["a"], "train_ids": ["a"], "val_ids": []}).encode()
    metadata = json.dumps({"a": {"time_id": 0, "warp_id": 0}}).encode()
    scene = json.dumps({"center": [0, 0, 0], "scale": 1.0, "near": 0.1, "far": 2.0}).encode()
    camera = json.dumps({"orientation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "position": [0, 0, -4],
                         "focal_length": 3, "principal_point": [2, 1.5], "pixel_aspect_ratio": 1,
                         "skew": 0, "radial_distortion": [0.01, 0, 0], "tangential_distortion": [0, 0],
                         "image_size": [4, 3]}).encode()
    write("nerfies_json", "one_frame", joined(dataset, metadata, scene, camera))


def npy_file(descr, fortran, shape, payload):
    header = "{'descr': '%s', 'fortran_order': %s, 'shape': %s, }" % (descr, fortran, shape)
    while (10 + len(header) + 1) % 64:
        header += " "
    header += "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode() + payload


def npy():
    write("npy", "f4_2x3", npy_file("<f4", "False", "(2, 3)", struct.pack("<6f", *range(6))))
    write("npy", "f8_fortran_1x17", npy_file(">f8", "True", "(1, 17)", struct.pack(">17d", *range(17))))


def masks():
    write("mask_png", "gray8", png(4, 3, 8, 0, [bytes([0, 1, 2, 3])] * 3))
    write("mask_png", "gray16", png(2, 2, 16, 0, [struct.pack(">2H", 0, 300)] * 2))
    write("mask_png", "rgb_refused", png(2, 1, 8, 2, [bytes(6)]))


def archives():
    files = {"scene/transforms.json": b"{}", "scene/images/a.png": b"\x89PNG"}
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("scene/", b"")
        for name, data in files.items():
            archive.writestr(name, data)
    write("archive", "zip", buffer.getvalue())
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w", format=tarfile.USTAR_FORMAT) as archive:
        for name, data in files.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            archive.addfile(info, io.BytesIO(data))
    write("archive", "tar", buffer.getvalue())
    write("archive", "tar_gz", gzip.compress(buffer.getvalue(), mtime=0))


if __name__ == "__main__":
    colmap()
    ply()
    transforms()
    nerfies()
    npy()
    masks()
    archives()
