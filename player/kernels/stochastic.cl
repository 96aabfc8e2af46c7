// Stochastic tiling of a quilted torus (mode tiles, outputs larger than the torus): random
// windows of the torus, one per vertex of a triangle grid, blended with Heitz and Neyret's
// histogram-preserving operator (High-Performance By-Example Noise using a
// Histogram-Preserving Blending Operator, 2018). The numpy reference is
// player/engines/stochastic_reference.py; both compute the same integers, so the results
// are equal.
//
// Triangle grid: rows of CELL_H pixels; row j's vertices sit at x = (k - 2) CELL_W + (j & 1)
// CELL_W / 2 (vertex column k of the table, k >= 0). Pixel (y, x): band j = y / CELL_H,
// r = y - j CELL_H, xs = x + CELL_W - (j & 1) CELL_W / 2, cell i = xs / CELL_W, c = xs - i CELL_W.
// weights[r CELL_W + c] = (W0, W1, W2, code): the blend weights of the pixel's three vertices
// (256ths) and code = tri + 4 single, tri naming the triangle of the cell (0: T0 B-1 B0,
// 1: T0 T1 B0, 2: T1 B0 B1; T top row j, B bottom row j + 1, indices relative to the cell)
// and single (1..3) the one vertex that alone shows there (0: a blend).
//
// vertices[v] = (oy, ox, frame, w): the window of vertex v is the torus shifted by (oy, ox),
// played at stored frame `frame` blended with the next one by w / 255.
//
// One window: out = tone[ch][((255 - w) a + w b + 127) / 255] (integers, as the gather; the
// tone table is min(255, (m gain + 128) >> 8), gain in 256ths).
// A blend, in integers: the torus Gaussianized once at open (bytes, 128 the mean, 32 levels a
// standard deviation), d_k = (255 - w_k) a_k + w_k b_k - 128 255 per window and channel,
// out = inverse[ch][inverse_index(W0 d0 + W1 d1 + W2 d2)] (the inverse table holds the tone too).
//
// Two passes: stochastic_copy draws every pixel as one window alone would, stochastic_blend then
// draws the blend pixels only (a list of one cell's runs, at every cell), so neither branches on the
// pixel's kind. Each window is read with weight 0 too where it has one (it adds nothing).
//
// Defines: TORUS_H, TORUS_W, TORUS_WP (its row pitch, TORUS_W + RUN), NFRAMES (the stored torus), CELL_H, CELL_W (triangle rows and
// width, CELL_W even), VCOLS (vertex columns per row), CELLS_X (cells per band), NRUNS (runs of
// blend pixels per cell), RUN (pixels per work-item of pass 1), N_INVERSE, PIXEL_BYTES, R_AT, G_AT,
// B_AT, A_AT (output pixel layout; A_AT -1: none).

inline void put(__global uchar *o, const uchar r, const uchar g, const uchar b)
{
    o[R_AT] = r;
    o[G_AT] = g;
    o[B_AT] = b;
#if A_AT >= 0
    o[A_AT] = 255;
#endif
}

// 16 pixels, their bytes in RGB order in rgb, to the output layout
inline void put16(__global uchar *o, const uchar *rgb)
{
    for (int l = 0; l < 16; ++l)
        put(o + l * PIXEL_BYTES, rgb[3 * l], rgb[3 * l + 1], rgb[3 * l + 2]);
}

// the torus pixel of window v at output (y, x), given ym = y mod TORUS_H and xm = x mod TORUS_W
inline int window_pixel(const int4 v, const int ym, const int xm)
{
    int ty = ym + v.x, tx = xm + v.y;
    ty -= ty >= TORUS_H ? TORUS_H : 0;
    tx -= tx >= TORUS_W ? TORUS_W : 0;
    return ty * TORUS_WP + tx;
}

inline int next_frame(const int f)
{
    return f + 1 == NFRAMES ? 0 : f + 1;
}

// the window's Gaussianized level (three channels, the time-interpolated byte minus 128, in 255ths)
// at pixel p of the Gaussianized torus
inline int3 level(__global const uchar *gauss, const int4 v, const int p)
{
    const int3 a = convert_int3(vload3((size_t)v.z * (TORUS_H * TORUS_WP) + p, gauss));
    const int3 b = convert_int3(vload3((size_t)next_frame(v.z) * (TORUS_H * TORUS_WP) + p, gauss));
    return (255 - v.w) * a + v.w * b - 128 * 255;
}

// the inverse table's entry of a blend acc = sum W_k d_k (W in 256ths): STEPS = 16 entries per
// level, rounded; 257 / 4096 stands for 16 / 255; every operand stays positive and below 2^31
inline int3 inverse_index(const int3 acc)
{
    const int3 u = acc + (1 << 25);
    return clamp((((u >> 8) * 257 + 2048) >> 12) - (8224 - N_INVERSE / 2), 0, N_INVERSE - 1);
}

// the three vertex indices of triangle tri of the cell (band j, cell i)
inline int3 triangle(const int tri, const int top, const int bottom, const int i, const int odd)
{
    return tri == 0 ? (int3)(top + i + 1, bottom + i + odd, bottom + i + 1 + odd)
         : tri == 1 ? (int3)(top + i + 1, top + i + 2, bottom + i + 1 + odd)
                    : (int3)(top + i + 2, bottom + i + 1 + odd, bottom + i + 2 + odd);
}

// the window that pixel x of band j (row r of the band) copies in pass 1: the vertex of the
// pixel's hexagon (copy[r CELL_W + c] = tri + 4 k, k = 1..3 the triangle's vertex)
inline int copy_vertex(__global const uchar *copy, const int x, const int r, const int top, const int bottom, const int odd)
{
    const int xs = x + CELL_W - odd * (CELL_W / 2);
    const int i = xs / CELL_W;
    const int code = copy[r * CELL_W + xs - i * CELL_W];
    const int3 vid = triangle(code & 3, top, bottom, i, odd);
    return (code >> 2) == 1 ? vid.x : (code >> 2) == 2 ? vid.y : vid.z;
}

// ((255 - w) a + w b + 127) / 255, as (n + 1 + (n >> 8)) >> 8 (exact for 0 <= n < 65535)
inline int3 mix3(const int3 a, const int3 b, const int w)
{
    const int3 n = (255 - w) * a + w * b + 127;
    return (n + 1 + (n >> 8)) >> 8;
}

inline ushort16 mix16(const ushort16 a, const ushort16 b, const int w)
{
    const ushort16 n = (ushort16)(255 - w) * a + (ushort16)w * b + (ushort16)127;
    return (n + (ushort16)1 + (n >> (ushort16)8)) >> (ushort16)8;
}

// Pass 1, RUN pixels of a row per work-item: every pixel as the window of its hexagon alone
// shows it (pass 2 overwrites the blend pixels). A run inside one hexagon (the window is the same
// at both its ends: a hexagon meets a row in one interval) is copied with whole vectors: the
// torus rows carry RUN pixels of their start again (TORUS_WP = TORUS_W + RUN), so a run never
// wraps; the tone of channel value m is min(255, (m gain + 128) >> 8), gain in 256ths per byte of
// the run (gains[48]); formats other than RGB place the run's 48 bytes pixel by pixel from private
// memory. Other runs, pixel by pixel, the same integers.
__kernel void stochastic_copy(
    __global const uchar *torus,      // NFRAMES x TORUS_H x TORUS_WP x 3
    __global const uchar *copy,       // CELL_H x CELL_W: the hexagon's vertex (tri + 4 k)
    __global const int4 *vertices,    // rows x VCOLS
    __global const uchar *tone,       // 3 x 256: tone of a single window
    __global const uint *gains,       // 3 x RUN: the tone gain (256ths) of each byte of a run
    __global uchar *out,
    const int width,
    const int height)
{
    const int x0 = get_global_id(0) * RUN;
    const int y = get_global_id(1);
    if (y >= height || x0 >= width)
        return;
    const int j = y / CELL_H;
    const int r = y - j * CELL_H;
    const int odd = j & 1;
    const int top = j * VCOLS, bottom = (j + 1) * VCOLS;
    const int x1 = min(x0 + RUN, width);
    const int ym = y % TORUS_H;
    const int first = copy_vertex(copy, x0, r, top, bottom, odd);
    if (x1 - x0 == RUN && first == copy_vertex(copy, x1 - 1, r, top, bottom, odd)) {
        const int4 v = vertices[first];
        const int p = window_pixel(v, ym, x0 % TORUS_W);
        __global const uchar *a = torus + ((size_t)v.z * (TORUS_H * TORUS_WP) + p) * 3;
        __global const uchar *b = torus + ((size_t)next_frame(v.z) * (TORUS_H * TORUS_WP) + p) * 3;
        __global uchar *o = out + ((size_t)y * width + x0) * PIXEL_BYTES;
#if PIXEL_BYTES == 3 && R_AT == 0 && G_AT == 1 && B_AT == 2
        for (int q = 0; q < 3; ++q) {
            const ushort16 m = mix16(convert_ushort16(vload16(q, a)), convert_ushort16(vload16(q, b)), v.w);
            const uint16 toned = (convert_uint16(m) * vload16(q, gains) + (uint16)128) >> 8;
            vstore16(convert_uchar16(min(toned, (uint16)255)), q, o);
        }
#else
        uchar rgb[48];
        for (int q = 0; q < 3; ++q) {
            const ushort16 m = mix16(convert_ushort16(vload16(q, a)), convert_ushort16(vload16(q, b)), v.w);
            const uint16 toned = (convert_uint16(m) * vload16(q, gains) + (uint16)128) >> 8;
            vstore16(convert_uchar16(min(toned, (uint16)255)), q, rgb);
        }
        put16(o, rgb);
#endif
        return;
    }
    int xm = x0 % TORUS_W;
    for (int x = x0; x < x1; ++x, xm = xm + 1 == TORUS_W ? 0 : xm + 1) {
        const int4 v = vertices[copy_vertex(copy, x, r, top, bottom, odd)];
        const int p = window_pixel(v, ym, xm);
        const int3 a = convert_int3(vload3((size_t)v.z * (TORUS_H * TORUS_WP) + p, torus));
        const int3 b = convert_int3(vload3((size_t)next_frame(v.z) * (TORUS_H * TORUS_WP) + p, torus));
        const int3 m = mix3(a, b, v.w);
        put(out + ((size_t)y * width + x) * PIXEL_BYTES, tone[m.x], tone[256 + m.y], tone[512 + m.z]);
    }
}

// one blend pixel (y, x) of weights wt, its three windows v (torus pixels p)
inline void blend_pixel(__global const uchar *gauss, __global const uchar *inverse, __global uchar *o, const int4 wt,
                        const int4 v0, const int4 v1, const int4 v2, const int ym, const int xm)
{
    const int3 acc = wt.x * level(gauss, v0, window_pixel(v0, ym, xm)) + wt.y * level(gauss, v1, window_pixel(v1, ym, xm))
                   + wt.z * level(gauss, v2, window_pixel(v2, ym, xm));
    const int3 q = inverse_index(acc);
    put(o, inverse[q.x], inverse[N_INVERSE + q.y], inverse[2 * N_INVERSE + q.z]);
}

// Pass 2, one work-item per run of blend pixels: runs[k] = (r, c, n) of a cell, n <= RUN blend
// pixels from (r, c) on in one triangle (NRUNS of them), dimension 1 the cell (band j = id /
// CELLS_X, cell i = id - j CELLS_X). A whole run inside the output is blended with whole
// vectors (bytes of the run: wbytes holds each pixel's weights per byte, W_k at
// [(k CELL_H + r) CELL_W 3 + 3 c + ch]; chan the inverse table's offset of each byte), the
// inverse looked up byte by byte; other runs pixel by pixel, the same integers.
__kernel void stochastic_blend(
    __global const uchar *gauss,      // NFRAMES x TORUS_H x TORUS_WP x 3: the Gaussianized torus
    __global const int4 *weights,     // CELL_H x CELL_W: (W0, W1, W2) in 256ths, code
    __global const ushort *wbytes,    // 3 x CELL_H x CELL_W x 3: the weights per byte
    __global const int *chan,         // 3 RUN: N_INVERSE times the channel of each byte of a run
    __global const int4 *runs,        // NRUNS: (r, c, n, 0)
    __global const int4 *vertices,    // rows x VCOLS
    __global const uchar *inverse,    // 3 x N_INVERSE: the Gaussianizing table's inverse, toned
    __global uchar *out,
    const int width,
    const int height)
{
    const int k = get_global_id(0);
    const int cell = get_global_id(1);
    if (k >= NRUNS)
        return;
    const int j = cell / CELLS_X;
    const int i = cell - j * CELLS_X;
    const int4 run = runs[k];
    const int odd = j & 1;
    const int y = j * CELL_H + run.x;
    const int x0 = i * CELL_W + run.y - CELL_W + odd * (CELL_W / 2);
    if (y >= height || x0 >= width || x0 + run.z <= 0)
        return;
    const int4 wt0 = weights[run.x * CELL_W + run.y];
    const int3 vid = triangle(wt0.w & 3, j * VCOLS, (j + 1) * VCOLS, i, odd);
    const int4 v0 = vertices[vid.x], v1 = vertices[vid.y], v2 = vertices[vid.z];
    const int ym = y % TORUS_H;
    if (run.z == RUN && x0 >= 0 && x0 + RUN <= width) {
        const int xm = x0 % TORUS_W;
        __global const uchar *g0 = gauss + (size_t)window_pixel(v0, ym, xm) * 3;
        __global const uchar *g1 = gauss + (size_t)window_pixel(v1, ym, xm) * 3;
        __global const uchar *g2 = gauss + (size_t)window_pixel(v2, ym, xm) * 3;
        const size_t frame = (size_t)(TORUS_H * TORUS_WP) * 3;
        __global const ushort *w = wbytes + (size_t)(run.x * CELL_W + run.y) * 3;
        const size_t wk = (size_t)CELL_H * CELL_W * 3;
        __global uchar *o = out + ((size_t)y * width + x0) * PIXEL_BYTES;
#if !(PIXEL_BYTES == 3 && R_AT == 0 && G_AT == 1 && B_AT == 2)
        uchar rgb[48];
#endif
        for (int q = 0; q < 3; ++q) {
            int16 acc = convert_int16(vload16(q, w)) * ((255 - v0.w) * convert_int16(vload16(q, g0 + v0.z * frame))
                        + v0.w * convert_int16(vload16(q, g0 + next_frame(v0.z) * frame)) - 128 * 255);
            acc += convert_int16(vload16(q, w + wk)) * ((255 - v1.w) * convert_int16(vload16(q, g1 + v1.z * frame))
                   + v1.w * convert_int16(vload16(q, g1 + next_frame(v1.z) * frame)) - 128 * 255);
            acc += convert_int16(vload16(q, w + 2 * wk)) * ((255 - v2.w) * convert_int16(vload16(q, g2 + v2.z * frame))
                   + v2.w * convert_int16(vload16(q, g2 + next_frame(v2.z) * frame)) - 128 * 255);
            const int16 u = acc + (1 << 25);
            const int16 e = clamp((((u >> 8) * 257 + 2048) >> 12) - (8224 - N_INVERSE / 2), 0, N_INVERSE - 1)
                          + vload16(q, chan);
            int at[16];
            uchar value[16];
            vstore16(e, 0, at);
            for (int l = 0; l < 16; ++l)
                value[l] = inverse[at[l]];
#if PIXEL_BYTES == 3 && R_AT == 0 && G_AT == 1 && B_AT == 2
            vstore16(vload16(0, value), q, o);
#else
            vstore16(vload16(0, value), q, rgb);
#endif
        }
#if !(PIXEL_BYTES == 3 && R_AT == 0 && G_AT == 1 && B_AT == 2)
        put16(o, rgb);
#endif
        return;
    }
    for (int n = 0; n < run.z; ++n) {
        const int x = x0 + n;
        if (x >= 0 && x < width)
            blend_pixel(gauss, inverse, out + ((size_t)y * width + x) * PIXEL_BYTES, weights[run.x * CELL_W + run.y + n],
                        v0, v1, v2, ym, x % TORUS_W);
    }
}
