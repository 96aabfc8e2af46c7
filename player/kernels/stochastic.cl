// Stochastic tiling of a quilted torus (mode tiles, outputs larger than the torus): random
// windows of the torus, one per vertex of a triangle grid, blended with Heitz and Neyret's
// histogram-preserving operator (High-Performance By-Example Noise using a
// Histogram-Preserving Blending Operator, 2018). The numpy reference is
// player/engines/stochastic_reference.py; both compute the same floats in the same order
// (no contraction), so the results are equal.
//
// Triangle grid: rows of CELL_H pixels; row j's vertices sit at x = (k - 2) CELL_W + (j & 1)
// CELL_W / 2 (vertex column k of the table, k >= 0). Pixel (y, x): band j = y / CELL_H,
// r = y - j CELL_H, xs = x + CELL_W - (j & 1) CELL_W / 2, cell i = xs / CELL_W, c = xs - i CELL_W.
// weights[r CELL_W + c] = (W0, W1, W2, code): the normalised blend weights of the pixel's
// three vertices and code = tri + 4 single, tri naming the triangle of the cell (0: T0 B-1 B0,
// 1: T0 T1 B0, 2: T1 B0 B1; T top row j, B bottom row j + 1, indices relative to the cell)
// and single (1..3) the one vertex that alone shows there (0: a blend).
//
// vertices[v] = (oy, ox, frame, w): the window of vertex v is the torus shifted by (oy, ox),
// played at stored frame `frame` blended with the next one by w / 255.
//
// One window: out = tone[ch][((255 - w) a + w b + 127) / 255] (integers, as the gather).
// A blend: g_k = ((255 - w_k) T[a_k] + w_k T[b_k]) / 255 per window (T: the Gaussianizing
// table of the channel), G = (W0 g0 + W1 g1) + W2 g2 (a window of weight 0 is not read and
// adds nothing), out = inverse[ch][clamp(G ISCALE + N_INVERSE / 2, 0, N_INVERSE - 1)]
// (the inverse table holds the tone too).
//
// Defines: TORUS_H, TORUS_W, NFRAMES (the stored torus), CELL_H, CELL_W (triangle rows and
// width, CELL_W even), VCOLS (vertex columns per row), N_INVERSE, ISCALE (float), RUN (pixels
// per work-item), PIXEL_BYTES, R_AT, G_AT, B_AT, A_AT (output pixel layout; A_AT -1: none).

#pragma OPENCL FP_CONTRACT OFF

#define INV255 (1.0f / 255.0f)

inline void put(__global uchar *o, const uchar r, const uchar g, const uchar b)
{
    o[R_AT] = r;
    o[G_AT] = g;
    o[B_AT] = b;
#if A_AT >= 0
    o[A_AT] = 255;
#endif
}

// the torus pixel of window v at output (y, x), given ym = y mod TORUS_H and xm = x mod TORUS_W
inline int window_pixel(const int4 v, const int ym, const int xm)
{
    int ty = ym + v.x, tx = xm + v.y;
    ty -= ty >= TORUS_H ? TORUS_H : 0;
    tx -= tx >= TORUS_W ? TORUS_W : 0;
    return ty * TORUS_W + tx;
}

inline int next_frame(const int f)
{
    return f + 1 == NFRAMES ? 0 : f + 1;
}

// the window's Gaussianized colour (three channels) at pixel p
inline float3 gauss(__global const uchar *torus, __global const float *table, const int4 v, const int p)
{
    const int3 a = convert_int3(vload3((size_t)v.z * (TORUS_H * TORUS_W) + p, torus));
    const int3 b = convert_int3(vload3((size_t)next_frame(v.z) * (TORUS_H * TORUS_W) + p, torus));
    const float wa = (float)(255 - v.w), wb = (float)v.w;
    float3 g;
    g.x = (wa * table[a.x] + wb * table[b.x]) * INV255;
    g.y = (wa * table[256 + a.y] + wb * table[256 + b.y]) * INV255;
    g.z = (wa * table[512 + a.z] + wb * table[512 + b.z]) * INV255;
    return g;
}

inline int inverse_index(const float g)
{
    return (int)clamp(g * ISCALE + (float)(N_INVERSE / 2), 0.0f, (float)(N_INVERSE - 1));
}

__kernel void stochastic(
    __global const uchar *torus,      // NFRAMES x TORUS_H x TORUS_W x 3
    __global const float4 *weights,   // CELL_H x CELL_W
    __global const int4 *vertices,    // rows x VCOLS
    __global const float *table,      // 3 x 256: Gaussianizing table per channel
    __global const uchar *inverse,    // 3 x N_INVERSE: its inverse, toned
    __global const uchar *tone,       // 3 x 256: tone of a single window
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
    int xm = x0 % TORUS_W;
    for (int x = x0; x < x1; ++x, xm = xm + 1 == TORUS_W ? 0 : xm + 1) {
        const int xs = x + CELL_W - odd * (CELL_W / 2);
        const int i = xs / CELL_W;
        const int c = xs - i * CELL_W;
        const float4 wt = weights[r * CELL_W + c];
        const int code = (int)wt.w;
        const int tri = code & 3, single = code >> 2;
        int3 vid;
        if (tri == 0)
            vid = (int3)(top + i + 1, bottom + i + odd, bottom + i + 1 + odd);
        else if (tri == 1)
            vid = (int3)(top + i + 1, top + i + 2, bottom + i + 1 + odd);
        else
            vid = (int3)(top + i + 2, bottom + i + 1 + odd, bottom + i + 2 + odd);
        __global uchar *o = out + ((size_t)y * width + x) * PIXEL_BYTES;
        if (single) {
            const int4 v = vertices[single == 1 ? vid.x : single == 2 ? vid.y : vid.z];
            const int p = window_pixel(v, ym, xm);
            const int3 a = convert_int3(vload3((size_t)v.z * (TORUS_H * TORUS_W) + p, torus));
            const int3 b = convert_int3(vload3((size_t)next_frame(v.z) * (TORUS_H * TORUS_W) + p, torus));
            const int3 n = (255 - v.w) * a + v.w * b + 127;
            const int3 m = (n + 1 + (n >> 8)) >> 8;  // n / 255 for 0 <= n < 65535
            put(o, tone[m.x], tone[256 + m.y], tone[512 + m.z]);
            continue;
        }
        float3 acc = (float3)(0.0f);
        if (wt.x != 0.0f) {
            const int4 v = vertices[vid.x];
            acc = wt.x * gauss(torus, table, v, window_pixel(v, ym, xm));
        }
        if (wt.y != 0.0f) {
            const int4 v = vertices[vid.y];
            acc = acc + wt.y * gauss(torus, table, v, window_pixel(v, ym, xm));
        }
        if (wt.z != 0.0f) {
            const int4 v = vertices[vid.z];
            acc = acc + wt.z * gauss(torus, table, v, window_pixel(v, ym, xm));
        }
        put(o,
            inverse[inverse_index(acc.x)],
            inverse[N_INVERSE + inverse_index(acc.y)],
            inverse[2 * N_INVERSE + inverse_index(acc.z)]);
    }
}
