#!/usr/bin/env python3
"""Fails unless a PNG screenshot shows the cloth.

Usage: check_png.py FILE.png [red|blue|redblue]. Standard library only: decodes
8-bit RGB/RGBA PNGs, then checks that the image is not blank (many distinct
colours) and that enough pixels have the cloth's checker colour: red for
the lab (the default), blue for the flag (whose capsule is red), red or
blue for the cape example (its cape and skirt) and the drape example (its
two sheets).
"""
import struct
import sys
import zlib


def decode(path):
    data = open(path, "rb").read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        sys.exit(f"{path}: not a PNG")
    pos, idat, header = 8, b"", None
    while pos < len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + length]
        pos += 12 + length
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
    width, height, depth, color, _, _, interlace = header
    if depth != 8 or color not in (2, 6) or interlace:
        sys.exit(f"{path}: unsupported PNG (depth {depth}, colour type {color})")
    channels = 3 if color == 2 else 4
    raw = zlib.decompress(idat)
    stride = width * channels
    rows, prev, at = [], bytearray(stride), 0
    for _ in range(height):
        kind, line = raw[at], bytearray(raw[at + 1:at + 1 + stride])
        at += 1 + stride
        for i in range(stride):
            left = line[i - channels] if i >= channels else 0
            up = prev[i]
            corner = prev[i - channels] if i >= channels else 0
            if kind == 1:
                line[i] = (line[i] + left) & 255
            elif kind == 2:
                line[i] = (line[i] + up) & 255
            elif kind == 3:
                line[i] = (line[i] + (left + up) // 2) & 255
            elif kind == 4:
                p = left + up - corner
                pa, pb, pc = abs(p - left), abs(p - up), abs(p - corner)
                pred = left if pa <= pb and pa <= pc else up if pb <= pc else corner
                line[i] = (line[i] + pred) & 255
        rows.append(line)
        prev = line
    return width, height, channels, rows


def main():
    path = sys.argv[1]
    colour = sys.argv[2] if len(sys.argv) > 2 else "red"
    if colour == "red":
        def hue(r, g, b):
            return r > g + 50 and r > b + 50
    elif colour == "blue":
        def hue(r, g, b):
            return b > r + 50 and b > g + 30
    elif colour == "redblue":
        # The cape example: a red cape (edge-on at times) and a blue skirt.
        def hue(r, g, b):
            return (r > g + 50 and r > b + 50) or (b > r + 50 and b > g + 30)
    else:
        sys.exit(f"unknown colour {colour}: red, blue or redblue")
    width, height, channels, rows = decode(path)
    colours, matching = set(), 0
    for line in rows:
        for x in range(0, width * channels, channels):
            r, g, b = line[x], line[x + 1], line[x + 2]
            colours.add((r, g, b))
            if hue(r, g, b):
                matching += 1
    share = matching / (width * height)
    print(f"{path}: {width}x{height}, {len(colours)} colours, cloth-{colour} pixels {share:.1%}")
    if len(colours) < 100:
        sys.exit("the screenshot is blank or nearly one colour")
    if share < 0.005:
        sys.exit("the screenshot does not show the cloth")


main()
