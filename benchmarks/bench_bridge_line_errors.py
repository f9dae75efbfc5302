"""Line errors the bridge framing lets through: v1 (XOR) next to v2 (CRC-16), same frames.

    .venv/bin/python benchmarks/bench_bridge_line_errors.py [--frames 20000] [--seed 1]

Frames are ``AVG`` replies with random plausible values (≈ 80 bytes), framed
by drivers/bridge_protocol.py. Each error model corrupts every frame once
(the CR LF terminator is never touched, so the line still ends where it did):

* ``same-bit pair``: one bit position flipped in two different bytes (the
  case an XOR cannot see);
* ``random 2 bits``: two bits anywhere;
* ``burst <=16``: a burst of 2..16 bits, first and last flipped, the inside random;
* ``BER 1e-2``: every bit flipped with probability 0.01 (frames left intact skipped);
* ``high-bit byte``: one byte replaced by a random byte 0x80..0xFF.

"Undetected" counts corrupted frames that decode without error to different
fields (a wrong value handed to the fit); a decoder crash would be counted
separately as "crashed". Then every 1- and 2-bit error of one full AVG frame
(exhaustive, check digits included, CR LF excluded), and decode throughput,
frames/s, one core.
"""

from __future__ import annotations

import argparse
import random
import time
from collections.abc import Callable

from drivers.bridge_protocol import Framing, decode_frame, encode_frame
from drivers.faults import ProtocolError

Corrupt = Callable[[bytes, random.Random], bytes]


def avg_fields(rng: random.Random) -> list[object]:
    mean = [f"{rng.uniform(-260_000, 260_000):.3f}" for _ in range(3)]
    sd = [f"{rng.uniform(1, 40):.3f}" for _ in range(3)]
    t = rng.randint(1500, 2300)
    return ["AVG", rng.choice([50, 100, 200, 1000]), *mean, *sd, f"{t + rng.random():.2f}",
            t - rng.randint(0, 3), t + rng.randint(0, 3), 0]


def _flip(line: bytes, bits: list[int]) -> bytes:
    b = bytearray(line)
    for bit in bits:
        b[bit // 8] ^= 0x80 >> (bit % 8)
    return bytes(b)


def same_bit_pair(line: bytes, rng: random.Random) -> bytes:
    i, j = rng.sample(range(len(line) - 2), 2)
    k = rng.randrange(8)
    return _flip(line, [8 * i + k, 8 * j + k])


def random_two_bits(line: bytes, rng: random.Random) -> bytes:
    return _flip(line, rng.sample(range(8 * (len(line) - 2)), 2))


def burst16(line: bytes, rng: random.Random) -> bytes:
    n_bits = 8 * (len(line) - 2)
    length = rng.randint(2, 16)
    start = rng.randrange(n_bits - length + 1)
    inside = [start + i for i in range(1, length - 1) if rng.random() < 0.5]
    return _flip(line, [start, start + length - 1, *inside])


def ber_1e2(line: bytes, rng: random.Random) -> bytes:
    bits = [i for i in range(8 * (len(line) - 2)) if rng.random() < 0.01]
    return _flip(line, bits)


def high_bit_byte(line: bytes, rng: random.Random) -> bytes:
    b = bytearray(line)
    b[rng.randrange(len(line) - 2)] = rng.randint(0x80, 0xFF)
    return bytes(b)


MODELS: dict[str, Corrupt] = {
    "same-bit pair": same_bit_pair, "random 2 bits": random_two_bits, "burst <=16": burst16,
    "BER 1e-2": ber_1e2, "high-bit byte": high_bit_byte,
}


def run(n_frames: int, seed: int) -> None:
    rng = random.Random(seed)
    frames = [avg_fields(rng) for _ in range(n_frames)]
    print(f"{n_frames} AVG frames, seed {seed}\n")
    print("| error model | framing | corrupted | detected | undetected | crashed |")
    print("|---|---|---|---|---|---|")
    for name, corrupt in MODELS.items():
        for framing in ("v1", "v2"):
            fr: Framing = framing  # type: ignore[assignment]
            crng = random.Random(f"{seed}-{name}")  # same corruption for both framings
            corrupted = detected = undetected = crashed = 0
            for fields in frames:
                line = encode_frame(*fields, framing=fr)
                bad = corrupt(line, crng)
                if bad == line:
                    continue
                corrupted += 1
                try:
                    got = decode_frame(bad, framing=fr)
                except ProtocolError:
                    detected += 1
                    continue
                except Exception:  # noqa: BLE001 - a crash is what the benchmark looks for
                    crashed += 1
                    continue
                if got != [str(f) for f in fields]:
                    undetected += 1
                else:
                    detected += 1  # e.g. a flip inside the check digits' case: harmless
            print(f"| {name} | {framing} | {corrupted} | {detected} | "
                  f"{undetected} ({100 * undetected / max(corrupted, 1):.2f} %) | {crashed} |")
    print()
    exhaustive(frames[0])
    print()
    for framing in ("v1", "v2"):
        lines = [encode_frame(*f, framing=framing) for f in frames]  # type: ignore[arg-type]
        t0 = time.perf_counter()
        for line in lines:
            decode_frame(line, framing=framing)  # type: ignore[arg-type]
        dt = time.perf_counter() - t0
        print(f"decode {framing}: {len(lines) / dt:,.0f} frames/s "
              f"({1e6 * dt / len(lines):.1f} µs per {len(lines[0])}-byte frame)")


def exhaustive(fields: list[object]) -> None:
    """Every single and double bit error of one frame: how many decode to other fields."""
    want = [str(f) for f in fields]
    for framing in ("v1", "v2"):
        fr: Framing = framing  # type: ignore[assignment]
        line = encode_frame(*fields, framing=fr)
        n_bits = 8 * (len(line) - 2)
        total = undetected = 0
        for a in range(n_bits):
            for b in range(a, n_bits):
                bad = _flip(line, [a] if a == b else [a, b])
                total += 1
                try:
                    if decode_frame(bad, framing=fr) != want:
                        undetected += 1
                except ProtocolError:
                    pass
        print(f"exhaustive, {len(line)}-byte frame, {framing}: {undetected} of {total} "
              f"one- and two-bit errors undetected")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=20_000)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    run(args.frames, args.seed)


if __name__ == "__main__":
    main()
