// Stochastic tiling of a quilted torus (mode tiles, outputs larger than the torus): random
// windows of the torus, one per vertex of a triangle grid, blended with Heitz and Neyret's
// histogram-preserving operator (High-Performance By-Example Noise using a
// Histogram-Preserving Blending Operator, 2018). The numpy reference is
// player/engines/stochastic_reference.py; both compute the same integers, so the results
// are equal.
//
// Triangle grid: rows of CELL_H pixels; row j's vertices sit at x = (k - 2) CELL_W + (j & 1)
// CELL_W / 2 (vertex column k of the table, k >= 0). Cell (j, i) covers output rows j CELL_H + r
// (0 <= r < CELL_H) and columns i CELL_W + c - CELL_W + (j & 1) CELL_W / 2 (0 <= c < CELL_W); the
// vertices it reads are named by a code: 0, 1 the top row's T(i + 1), T(i + 2); 2, 3, 4 the bottom
// row's B(i + (j & 1)), B(i + 1 + (j & 1)), B(i + 2 + (j & 1)) (vertex_index).
//
// vertices[v] = (oy, ox, frame, w): the window of vertex v is the torus shifted by (oy, ox),
// played at stored frame `frame` blended with the next one by w / 255.
//
// The torus and its Gaussianized copy are stored as RGB bytes, every row carrying its first RUN
// pixels again (TORUS_WP = TORUS_W + RUN), so every operation is per byte and a piece never wraps.
// A piece is computed as RGB bytes; a four-byte output (RGBA, BGRA) gets them placed as it
// stores them (pixels.cl's put16, 16 whole pixels a vector; built in front of this file), so a
// piece reads and computes 3/4 of the bytes it writes.
//
// One window alone (a copy piece): byte = min(255, (((255 - w) a + w b + 127) / 255 gain + 128) >> 8),
// the gain in 256ths per byte (gains), the division by 255 as (n + 1 + (n >> 8)) >> 8.
// A blend (a blend piece): d_k = (255 - w_k) a_k + w_k b_k - 128 255 per window from the
// Gaussianized torus (bytes, 128 the mean, 32 levels a standard deviation), byte =
// inverse[chan][inverse_index(W0 d0 + W1 d1 + W2 d2)] (W in 256ths; the inverse table holds the
// tone too).
//
// Work: one cell's pixels are cut once at open into pieces of at most RUN pixels of a row, in row
// order, each either shown by one window alone (a copy piece) or blending the same three windows
// (a blend piece; a code repeated with weight 0 where two windows blend), so every output pixel
// is written once, by one kernel: one work-item per piece (dimension 0), dimension 1 the cell
// (band j = id / CELLS_X, cell i = id - j CELLS_X). A piece is computed as whole 16-byte vectors
// of RGB bytes; they are stored as vectors where all RUN pixels lie in the output, else pixel by
// pixel.
//
// Defines: TORUS_H, TORUS_W, TORUS_WP, NFRAMES (the stored torus), CELL_H, CELL_W (triangle rows
// and width, CELL_W even, at most TORUS_W), VCOLS (vertex columns per row), CELLS_X (cells per
// band), NPIECES (pieces per cell), RUN (pixels per piece at most, a multiple of 16), N_INVERSE,
// PIXEL_BYTES, R_AT, G_AT, B_AT, A_AT (pixels.cl).

#define PIECE_BYTES (3 * RUN)
#define FRAME_BYTES ((size_t)TORUS_H * TORUS_WP * 3)

// the vertex that code names for cell i of band j
inline int vertex_index(const int code, const int j, const int i)
{
    const int odd = j & 1;
    return code < 2 ? j * VCOLS + i + 1 + code : (j + 1) * VCOLS + i + code - 2 + odd;
}

inline size_t next_frame(const int f)
{
    return f + 1 == NFRAMES ? 0 : f + 1;
}

// the byte offset within a torus frame of window v's pixel at output (y, x), given ym = y mod
// TORUS_H and xm = x mod TORUS_W
inline size_t window_byte(const int4 v, const int ym, const int xm)
{
    int ty = ym + v.x, tx = xm + v.y;
    ty -= ty >= TORUS_H ? TORUS_H : 0;
    tx -= tx >= TORUS_W ? TORUS_W : 0;
    return ((size_t)ty * TORUS_WP + tx) * 3;
}

// the time-interpolated byte of window v at byte p of a frame, from the stored torus t
inline int interpolated(__global const uchar *t, const int4 v, const size_t p)
{
    return (255 - v.w) * t[(size_t)v.z * FRAME_BYTES + p] + v.w * t[next_frame(v.z) * FRAME_BYTES + p];
}

// (n + 1 + (n >> 8)) >> 8 for n / 255 (exact for 0 <= n < 65535)
inline ushort16 div255(const ushort16 n)
{
    return (n + (ushort16)1 + (n >> (ushort16)8)) >> (ushort16)8;
}

// the RGB bytes of a piece from private memory to the output, those of pixels lo .. hi - 1 only
inline void store_part(__global uchar *o, const uchar *bytes, const int lo, const int hi)
{
#if PIXEL_BYTES == 3
    for (int b = lo * 3; b < hi * 3; ++b)
        o[b] = bytes[b];
#else
    for (int k = lo; k < hi; ++k)
        put1(bytes[3 * k], bytes[3 * k + 1], bytes[3 * k + 2], o + 4 * k);
#endif
}

// 16 bytes (vector q) of window v alone, a and c its two frames: ((255 - w) a + w c + 127) / 255, toned
inline uchar16 copy16(__global const uchar *a, __global const uchar *c, const int w, __global const uint *gains,
                      const int toned, const int q)
{
    const ushort16 m = div255((ushort16)(255 - w) * convert_ushort16(vload16(q, a))
                              + (ushort16)w * convert_ushort16(vload16(q, c)) + (ushort16)127);
    return toned ? convert_uchar16(min((convert_uint16(m) * vload16(q, gains) + (uint16)128) >> 8, (uint16)255))
                 : convert_uchar16(m);
}

// a copy piece: pixels lo .. hi - 1 of the RUN from output (y, x0) as window v alone shows them
inline void copy_piece(__global const uchar *torus, const int4 v, __global const uint *gains, const int toned,
                       __global uchar *o, const int ym, const int xm, const int lo, const int hi)
{
    const size_t p = window_byte(v, ym, xm);
    __global const uchar *a = torus + (size_t)v.z * FRAME_BYTES + p;
    __global const uchar *c = torus + next_frame(v.z) * FRAME_BYTES + p;
    if (lo == 0 && hi == RUN) {
#if PIXEL_BYTES == 3
        for (int q = 0; q < PIECE_BYTES / 16; ++q)
            vstore16(copy16(a, c, v.w, gains, toned, q), q, o);
#else
        for (int g = 0; g < RUN / 16; ++g)
            put16(copy16(a, c, v.w, gains, toned, 3 * g), copy16(a, c, v.w, gains, toned, 3 * g + 1),
                  copy16(a, c, v.w, gains, toned, 3 * g + 2), o + 64 * g);
#endif
        return;
    }
    uchar bytes[PIECE_BYTES];
    for (int q = 0; q < PIECE_BYTES / 16; ++q)
        vstore16(copy16(a, c, v.w, gains, toned, q), q, bytes);
    store_part(o, bytes, lo, hi);
}

// the inverse table's entry of a blend acc = sum W_k d_k (W in 256ths): STEPS = 16 entries per
// level, rounded; 257 / 4096 stands for 16 / 255; every operand stays positive and below 2^31
inline int inverse_index(const int acc)
{
    const int u = acc + (1 << 25);
    return clamp((((u >> 8) * 257 + 2048) >> 12) - (8224 - N_INVERSE / 2), 0, N_INVERSE - 1);
}

// a blend piece: pixels lo .. hi - 1 of the RUN from output (y, x0), windows v0, v1, v2 weighted by w
inline void blend_piece(__global const uchar *gauss, const int4 v0, const int4 v1, const int4 v2,
                        __global const ushort *w, __global const int *chan, __global const uchar *inverse,
                        __global uchar *o, const int ym, const int xm, const int lo, const int hi)
{
    const size_t p0 = window_byte(v0, ym, xm), p1 = window_byte(v1, ym, xm), p2 = window_byte(v2, ym, xm);
    __global const uchar *a0 = gauss + (size_t)v0.z * FRAME_BYTES + p0, *b0 = gauss + next_frame(v0.z) * FRAME_BYTES + p0;
    __global const uchar *a1 = gauss + (size_t)v1.z * FRAME_BYTES + p1, *b1 = gauss + next_frame(v1.z) * FRAME_BYTES + p1;
    __global const uchar *a2 = gauss + (size_t)v2.z * FRAME_BYTES + p2, *b2 = gauss + next_frame(v2.z) * FRAME_BYTES + p2;
    const bool whole = lo == 0 && hi == RUN;
    uchar bytes[PIECE_BYTES];
    for (int q = 0; q < PIECE_BYTES / 16; ++q) {
        int16 acc = convert_int16(vload16(q, w)) * ((255 - v0.w) * convert_int16(vload16(q, a0))
                    + v0.w * convert_int16(vload16(q, b0)) - 128 * 255);
        acc += convert_int16(vload16(q, w + PIECE_BYTES)) * ((255 - v1.w) * convert_int16(vload16(q, a1))
               + v1.w * convert_int16(vload16(q, b1)) - 128 * 255);
        acc += convert_int16(vload16(q, w + 2 * PIECE_BYTES)) * ((255 - v2.w) * convert_int16(vload16(q, a2))
               + v2.w * convert_int16(vload16(q, b2)) - 128 * 255);
        const int16 u = acc + (1 << 25);
        const int16 e = clamp((((u >> 8) * 257 + 2048) >> 12) - (8224 - N_INVERSE / 2), 0, N_INVERSE - 1)
                      + vload16(q, chan);
        int at[16];
        vstore16(e, 0, at);
        for (int l = 0; l < 16; ++l)
            bytes[16 * q + l] = inverse[at[l]];
#if PIXEL_BYTES == 3
        if (whole)
            vstore16(vload16(q, bytes), q, o);
#endif
    }
#if PIXEL_BYTES == 4
    if (whole) {
        for (int g = 0; g < RUN / 16; ++g)
            put16(vload16(3 * g, bytes), vload16(3 * g + 1, bytes), vload16(3 * g + 2, bytes), o + 64 * g);
        return;
    }
#endif
    if (!whole)
        store_part(o, bytes, lo, hi);
}

// One work-item per piece (dimension 0, NPIECES of a cell in row order), dimension 1 the cell.
__kernel void stochastic(
    __global const uchar *torus,      // NFRAMES x TORUS_H x TORUS_WP x 3 (RGB)
    __global const uchar *gauss,      // the same, Gaussianized
    __global const int8 *pieces,      // NPIECES: (r, c, n, blend, code0, code1, code2, its row of wbytes)
    __global const ushort *wbytes,    // blend pieces x 3 x PIECE_BYTES: W of each window at each RGB byte
    __global const int *chan,         // PIECE_BYTES: the inverse table's offset of each RGB byte
    __global const uint *gains,       // PIECE_BYTES: the tone gain (256ths) of each RGB byte of a piece
    const int toned,                  // 0: every gain is 256 (one window's bytes are m itself)
    __global const int4 *vertices,    // rows x VCOLS
    __global const uchar *inverse,    // 3 x N_INVERSE: the Gaussianizing table's inverse, toned
    __global uchar *out,
    const int width,
    const int height)
{
    const int k = get_global_id(0);
    const int cell = get_global_id(1);
    if (k >= NPIECES)
        return;
    const int8 piece = pieces[k];
    const int j = cell / CELLS_X;
    const int i = cell - j * CELLS_X;
    const int y = j * CELL_H + piece.s0;
    const int x0 = i * CELL_W + piece.s1 - CELL_W + (j & 1) * (CELL_W / 2);
    const int lo = max(0, -x0), hi = min(piece.s2, width - x0);
    if (y >= height || lo >= hi)
        return;
    // x0 >= -CELL_W > -TORUS_W
    const int ym = y % TORUS_H, xm = (x0 + TORUS_W) % TORUS_W;
    __global uchar *o = out + ((size_t)y * width + x0) * PIXEL_BYTES;
    const int4 v0 = vertices[vertex_index(piece.s4, j, i)];
    if (!piece.s3) {
        copy_piece(torus, v0, gains, toned, o, ym, xm, lo, hi);
        return;
    }
    const int4 v1 = vertices[vertex_index(piece.s5, j, i)];
    const int4 v2 = vertices[vertex_index(piece.s6, j, i)];
    blend_piece(gauss, v0, v1, v2, wbytes + (size_t)piece.s7 * (3 * PIECE_BYTES), chan, inverse, o, ym, xm, lo, hi);
}
