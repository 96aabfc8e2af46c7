// Motion-compensated crossfade of two stored frames a and b along their midpoint flow f
// (a(p - f/2) matches b(p + f/2)), in exact integer arithmetic (player/warp.py is the reference):
//     f(p)  = bilinear flow at pixel p from the grid (samples every 2^STEP_LOG2 pixels), in 1/16 px
//     out(p) = (wa * A(16 p - (wb f + 128) >> 8) + wb * B(16 p + (wa f + 128) >> 8) + 32768) >> 16
// where A, B are bilinear samples (16 x 16 weights, edge pixels repeated) of a, b in 8.8 fixed
// point, and wa + wb = 256. Every shift of a possibly negative value floors (FLOOR_SHIFT), so the
// result does not depend on how a device shifts negative integers.
//
// One work-item per output pixel, global size (W, H). frames: T RGB frames FRAME_STRIDE bytes
// apart (rows of W pixels); flows: grid (GH, GW, 2) shorts (x, y) per pair. Output pixels of
// PIXEL_BYTES bytes, the colours at R_AT, G_AT, B_AT, alpha 255 at A_AT (-1: none).
//
// Defines: W, H, FRAME_STRIDE, GH, GW, STEP_LOG2, PIXEL_BYTES, R_AT, G_AT, B_AT, A_AT.

#define FLOOR_SHIFT(v, k) ((v) >= 0 ? (v) >> (k) : -((-(v) + (1 << (k)) - 1) >> (k)))

inline int sample(__global const uchar *f, int px, int py, int c)
{
    const int x0 = FLOOR_SHIFT(px, 4), y0 = FLOOR_SHIFT(py, 4);
    const int fx = px - x0 * 16, fy = py - y0 * 16;
    const int xa = clamp(x0, 0, W - 1), xb = clamp(x0 + 1, 0, W - 1);
    const int ya = clamp(y0, 0, H - 1), yb = clamp(y0 + 1, 0, H - 1);
    const int p00 = f[(ya * W + xa) * 3 + c], p01 = f[(ya * W + xb) * 3 + c];
    const int p10 = f[(yb * W + xa) * 3 + c], p11 = f[(yb * W + xb) * 3 + c];
    return (p00 * (16 - fx) + p01 * fx) * (16 - fy) + (p10 * (16 - fx) + p11 * fx) * fy;
}

__kernel void warp2(__global const uchar *restrict frames,
                    __global const short *restrict flows,
                    const int ia, const int ib, const int wa, const int wb, const int pair,
                    __global uchar *restrict out)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= W || y >= H)
        return;
    const int s = 1 << STEP_LOG2;
    const int gx = x >> STEP_LOG2, gy = y >> STEP_LOG2, rx = x & (s - 1), ry = y & (s - 1);
    __global const short *g = flows + (size_t)pair * GH * GW * 2;
    const int w00 = (s - rx) * (s - ry), w01 = rx * (s - ry), w10 = (s - rx) * ry, w11 = rx * ry;
    const int i00 = (gy * GW + gx) * 2, i01 = i00 + 2, i10 = i00 + GW * 2, i11 = i10 + 2;
    const int rnd = (s * s) >> 1;
    int fx = g[i00] * w00 + g[i01] * w01 + g[i10] * w10 + g[i11] * w11 + rnd;
    int fy = g[i00 + 1] * w00 + g[i01 + 1] * w01 + g[i10 + 1] * w10 + g[i11 + 1] * w11 + rnd;
    fx = FLOOR_SHIFT(fx, 2 * STEP_LOG2);
    fy = FLOOR_SHIFT(fy, 2 * STEP_LOG2);
    const int dax = wb * fx + 128, day = wb * fy + 128, dbx = wa * fx + 128, dby = wa * fy + 128;
    const int ax = x * 16 - FLOOR_SHIFT(dax, 8), ay = y * 16 - FLOOR_SHIFT(day, 8);
    const int bx = x * 16 + FLOOR_SHIFT(dbx, 8), by = y * 16 + FLOOR_SHIFT(dby, 8);
    __global const uchar *a = frames + (size_t)ia * FRAME_STRIDE, *b = frames + (size_t)ib * FRAME_STRIDE;
    __global uchar *o = out + ((size_t)y * W + x) * PIXEL_BYTES;
    uchar v[3];
    for (int c = 0; c < 3; ++c)
        v[c] = (uchar)((wa * sample(a, ax, ay, c) + wb * sample(b, bx, by, c) + 32768) >> 16);
    put1(v[0], v[1], v[2], o);
}
