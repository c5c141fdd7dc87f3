#!/usr/bin/env python3
"""How tile order in a pack affects reading a rectangular view (docs/pack-format.md, "Order").

For random W x H windows of tiles in a 128 x 128 level, count the contiguous runs of tiles a
reader must fetch and the span (first to last tile) the window covers, with tiles stored in
raster order and in Morton order. Deterministic (fixed seed); no timing involved.
    python3 bench/order-locality.py
"""
import random


def morton(x, y):
    r = 0
    for b in range(16):
        r |= ((x >> b) & 1) << (2 * b) | ((y >> b) & 1) << (2 * b + 1)
    return r


def main():
    random.seed(1)
    n, trials = 128, 2000
    print("| window | tiles | raster runs | Morton runs | raster span | Morton span |")
    print("|---|---:|---:|---:|---:|---:|")
    for w, h in [(4, 4), (8, 6), (16, 9), (32, 32)]:
        totals = [0, 0, 0, 0]
        for _ in range(trials):
            x0, y0 = random.randrange(n - w), random.randrange(n - h)
            cells = [(x, y) for y in range(y0, y0 + h) for x in range(x0, x0 + w)]
            for i, key in enumerate([lambda x, y: y * n + x, morton]):
                s = sorted(key(x, y) for x, y in cells)
                totals[i] += 1 + sum(1 for a, b in zip(s, s[1:]) if b != a + 1)
                totals[2 + i] += s[-1] - s[0] + 1
        r, m, rs, ms = (t / trials for t in totals)
        print(f"| {w}x{h} | {w * h} | {r:.1f} | {m:.1f} | {rs:.0f} | {ms:.0f} |")


if __name__ == "__main__":
    main()
