"""Exact neighbourhood sums ρ, Σo, Σ|o|² over a lattice ball stencil, from column bit masks.

Alg. 1 needs, for every voxel p of P*_d, the sums of [1, o, |o|²] over the occupied stencil cells
p + o. Gathering the K = 123 stencil cells of every voxel (K·N byte gathers plus a K×5 product)
is the cost of a from-scratch detection. Here the occupancy of every (x, y) column is one
integer whose bits are the z cells, so the stencil cells of one stencil column (dx, dy) are one
bit window of one word, and a lookup table indexed by that window gives the column's packed
contribution to all five sums at once. Two stencil columns share one word and one lookup: their
z bits are interleaved (column a on even bits, b on odd bits), so a voxel needs ~K/8 gathers,
shifts, masks and lookups instead of K gathers and a float product. The sums are small
integers packed into one int64 (signed bit fields, linear under addition), so the result is
bit-identical to the gather path whatever the order of additions.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

# One int64 holds all five sums as signed bit fields (ρ, Σo_x, Σo_y, Σo_z, Σ|o|²): addition
# is linear, so adding packed contributions adds every field at once; fields are wide enough
# for any stencil with r_s ≤ 3 voxels (K ≤ 123: |Σo| ≤ 369, Σ|o|² ≤ 1107).
FIELD_BITS = (9, 10, 10, 10, 12)
MAX_K = 123  # ρ ≤ K also fits the signed field `unpack_fields` undoes
# Σo is shifted by +2^9 so every field of a finished sum is non-negative (|Σo| ≤ 369 < 2^9)
_BIAS = np.array([0, 512, 512, 512, 0], np.int64)
LANES = 2  # stencil columns interleaved in one word
WORD_Z = 64 // LANES  # z cells one lane holds (a band of z plus the stencil's reach)
EXACT_BITS = 53  # float64 sums of distinct powers of two below 2^53 are exact


def pack_fields(rows: np.ndarray) -> np.ndarray:
    """(..., 5) signed ints → (...) int64 packed sums."""
    out = np.zeros(rows.shape[:-1], np.int64)
    shift = 0
    for i, bits in enumerate(FIELD_BITS):
        out += rows[..., i].astype(np.int64) << shift
        shift += bits
    return out


_BIAS_PACKED = int(pack_fields(_BIAS))


def unpack_fields(packed: np.ndarray) -> np.ndarray:
    """(N,) int64 packed sums → (5, N) int64 fields (lowest field first, borrows undone)."""
    v = packed.copy()
    out = np.empty((len(FIELD_BITS), packed.size), np.int64)
    for i, bits in enumerate(FIELD_BITS):
        half = 1 << (bits - 1)
        field = out[i]  # ((v + half) & mask) - half, in place: no temporaries per field
        np.add(v, half, out=field)
        np.bitwise_and(field, (1 << bits) - 1, out=field)
        field -= half
        v -= field
        v >>= bits
    return out


def column_groups(offsets: np.ndarray) -> list[tuple[np.ndarray, int, np.ndarray]]:
    """Stencil columns grouped by LANES: [(dxdy (k, 2), half-height h, packed LUT)].

    Columns of equal half-height h (|dz| ≤ h) share a group, so a group's window is 2h + 1
    cells per lane and its table has 2^(LANES·(2h+1)) entries (at most 2^14 for r_s = 3).
    """
    cols, inv = np.unique(offsets[:, :2], axis=0, return_inverse=True)
    inv = inv.ravel()
    heights = np.array([np.abs(offsets[inv == j, 2]).max() for j in range(len(cols))])
    order = np.lexsort((cols[:, 1], cols[:, 0], -heights))
    rows = np.c_[np.ones(len(offsets), np.int64), offsets, (offsets**2).sum(1)]
    groups = []
    i = 0
    while i < len(order):
        h = int(heights[order[i]])
        members = [order[i]]
        while (len(members) < LANES and i + len(members) < len(order)
               and heights[order[i + len(members)]] == h):
            members.append(order[i + len(members)])
        i += len(members)
        width = 2 * h + 1
        window = np.arange(1 << (LANES * width))
        table = np.zeros((window.size, 5), np.int64)
        for lane, j in enumerate(members):
            for k in np.flatnonzero(inv == j):
                bit = LANES * (int(offsets[k, 2]) + h) + lane
                table += ((window >> bit) & 1)[:, None] * rows[k]
        groups.append((cols[members], h, pack_fields(table)))
    return groups


def _spread(w: np.ndarray) -> np.ndarray:
    """Bits of (N,) uint64 words below 2^32 moved from position q to LANES·q (LANES = 2)."""
    for shift, mask in ((16, 0x0000FFFF0000FFFF), (8, 0x00FF00FF00FF00FF),
                        (4, 0x0F0F0F0F0F0F0F0F), (2, 0x3333333333333333),
                        (1, 0x5555555555555555)):
        w = (w | (w << np.uint64(shift))) & np.uint64(mask)
    return w


def fits(offsets: np.ndarray) -> bool:
    """Whether `ball_sums` handles this stencil: every biased field stays in its bits and a
    band of z plus the reach fits one lane."""
    a = np.abs(offsets)
    return bool(len(offsets) <= MAX_K and a.sum(0).max() < _BIAS[1]
                and (offsets**2).sum() < 1 << FIELD_BITS[4] and a[:, 2].max() < WORD_Z // 2)


def ball_sums(indices: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(5, N) int64 [ρ, Σo_x, Σo_y, Σo_z, Σ|o|²] over occupied cells p + o, o ∈ `offsets`,
    for unique (N, 3) lattice indices; `offsets` (K, 3) int64 must pass `fits`."""
    n = indices.shape[0]
    if not fits(offsets):
        raise ValueError("stencil too large for the packed sums (FIELD_BITS, WORD_Z)")
    if n == 0:
        return np.zeros((len(FIELD_BITS), 0), np.int64)
    reach = int(np.abs(offsets[:, 2]).max())
    pad = int(np.abs(offsets[:, :2]).max())
    band = WORD_Z - 2 * reach  # z cells per band whose whole reach fits one lane
    x, y, z = indices[:, 0], indices[:, 1], indices[:, 2]
    x_lo, y_lo = int(x.min()) - pad, int(y.min()) - pad
    ny = int(y.max()) - y_lo + pad + 1
    ncol = (int(x.max()) - x_lo + pad + 1) * ny
    col = (x - x_lo) * ny + (y - y_lo)  # padded (x, y) column, row-major
    z = z - z.min()
    margin = pad * (ny + 1)  # |dx·ny + dy| of any stencil column
    groups = _groups(np.ascontiguousarray(offsets, np.int64).tobytes(), len(offsets))
    out = np.empty(n, np.int64)
    z_top = int(z.max()) + 1
    full_lo, full = 0, None
    for z0 in range(0, z_top, band):
        if full is None or min(z0 + band + reach, z_top) > full_lo + EXACT_BITS:
            # z cell of column C at bit z − full_lo of full[C]: a column's cells are distinct
            # powers of two below 2^53, so a float64 bincount sums them exactly
            full_lo = z0 - reach
            near = np.flatnonzero((z >= full_lo) & (z < full_lo + EXACT_BITS))
            cn, zn = (col, z) if near.size == n else (col[near], z[near])
            full = np.bincount(cn, np.ldexp(1.0, zn - full_lo), ncol).astype(np.uint64)
        # this band's lane: cells z0 − reach ≤ z < z0 + band + reach at bit LANES·(z − z0 + reach)
        lane0 = _spread((full >> np.uint64(z0 - reach - full_lo)) & np.uint64(0xFFFFFFFF))
        sel = np.flatnonzero((z >= z0) & (z < z0 + band))
        if z0 == 0 and sel.size == n:
            sel = slice(None)  # one band holds every voxel: no index copies
        c = col[sel]
        start = np.uint64(LANES) * (z[sel] - z0).astype(np.uint64)
        acc = np.full(c.shape[0], _BIAS_PACKED)  # every field ends ≥ 0: no borrows to undo
        w = np.empty(c.shape[0], np.uint64)
        looked_up = np.empty(c.shape[0], np.int64)  # reused buffers; "clip": unbuffered `out`
        # lanes shifted down by the reach − h cells no window of half-height h reads: every
        # window then starts at bit LANES·(z − z0); `margin` zero words each side make every
        # column shift a plain slice
        padded = np.zeros(ncol + 2 * margin, np.uint64)
        padded[margin : margin + ncol] = lane0
        lanes = {}
        for dxdy, h, _ in groups:
            if (h, 0) not in lanes:
                lanes[h, 0] = padded >> np.uint64(LANES * (reach - h)) if h < reach else padded
            if len(dxdy) > 1 and (h, 1) not in lanes:
                lanes[h, 1] = lanes[h, 0] << np.uint64(1)
        words = np.empty(ncol, np.uint64)
        for dxdy, h, table in groups:
            # lane j of word C holds column C + dxdy[j]
            shifted = [lanes[h, j][margin + s : margin + s + ncol]
                       for j, s in enumerate(dxdy[:, 0] * ny + dxdy[:, 1])]
            src = np.bitwise_or(*shifted, out=words) if len(shifted) == 2 else shifted[0]
            np.take(src, c, out=w, mode="clip")
            w >>= start
            w &= np.uint64((1 << (LANES * (2 * h + 1))) - 1)
            acc += np.take(table, w.view(np.int64), out=looked_up, mode="clip")
        out[sel] = acc
    return _unpack_biased(out)


def _unpack_biased(packed: np.ndarray) -> np.ndarray:
    """(N,) packed sums that include _BIAS → (5, N) int64 fields (two or three ops each)."""
    out = np.empty((len(FIELD_BITS), packed.size), np.int64)
    shift = 0
    for i, bits in enumerate(FIELD_BITS):
        np.bitwise_and(packed >> shift if shift else packed, (1 << bits) - 1, out=out[i])
        if _BIAS[i]:
            out[i] -= _BIAS[i]
        shift += bits
    return out


@lru_cache(maxsize=8)
def _groups(offsets_bytes: bytes, k: int) -> list[tuple[np.ndarray, int, np.ndarray]]:
    return column_groups(np.frombuffer(offsets_bytes, np.int64).reshape(k, 3))
