// Shared gather machinery (modes tiles, quilt, ...): every output pixel is read from a
// stack of stored frames at a per-pixel source pixel and a per-pixel time, blended
// linearly between the two neighbouring stored frames and passed through a per-source
// colour-tone stage  v * gain[tone] + offset[tone].
//
// A packed source entry is (tone << 24) | (y * FRAME_W + x): a pixel of one stored frame
// plus the index of its tone. The source is either a per-pixel map (GRID == 0, one entry
// per output pixel) or a grid of cells (GRID == 1, one entry per cell naming the cell's
// top-left pixel; the pixel at (dy, dx) inside the cell reads origin + dy * FRAME_W + dx).
//
// The time map is sampled bilinearly at a step of TSTEP output pixels (TSTEP == 1: one
// value per pixel): time(y, x) = t0 + map((y + 0.5) / TSTEP - 0.5, (x + 0.5) / TSTEP - 0.5).
//
// Defines: FRAME_W, FRAME_PIXELS (stored frame width, width * height), NFRAMES, GRID,
// CELL_H, CELL_W (cell size of the grid; compile-time so the divisions become multiplies),
// WRAP (0 loop, 1 clamp, 2 ping-pong), INTERP (1: linear in time, 0: nearest earlier
// frame), TSTEP, RUN (pixels per work-item).

#define WRAP_LOOP 0
#define WRAP_CLAMP 1
#define WRAP_PINGPONG 2

inline int wrap_index(int i)
{
#if WRAP == WRAP_LOOP
    int m = i % NFRAMES;
    return m < 0 ? m + NFRAMES : m;
#elif WRAP == WRAP_CLAMP
    return clamp(i, 0, NFRAMES - 1);
#else
#if NFRAMES == 1
    return 0;
#else
    const int period = 2 * (NFRAMES - 1);
    int m = i % period;
    m = m < 0 ? m + period : m;
    return m < NFRAMES ? m : period - m;
#endif
#endif
}

// floor() is a slow library call in PoCL; this is exact for |v| < 2^31.
inline int fast_floor(float v)
{
    const int i = (int)v;
    return i - (int)((float)i > v);
}


#if TSTEP == 8
// Vectorised variant for a time lattice of step 8. A work-item renders the VRUN pixels
// [VRUN k - 4, VRUN (k + 1) - 4) of each of ROWS rows, in runs of 16 pixels (48 bytes) that
// cover two lattice intervals, so that the time of lanes 0-7 and of lanes 8-15 is linear in x
// and is computed as one float16 (the same per-pixel formula as the numpy reference). A run
// whose source is linear (one tile cell, or two cells split at a boundary: bytes merged
// before the blend) and whose frame indices span at most two neighbours moves 48 bytes per
// frame with under-aligned 16-byte loads (three frames when the run crosses a frame
// boundary) and blends and tones in three float16, tone factors pre-expanded per byte on the
// host (TONE_STRIDE); the runs that reach past a row's ends store only their bytes inside
// it. Any other run falls back to the per-pixel path. (Runs of 32 pixels were tried: their
// frame span exceeds two neighbours too often under smoothed offsets, and they were slower.)
#define VRUN 128

// PoCL's vload16/vstore16 of uchar move byte by byte; an under-aligned vector type gives one
// unaligned 16-byte access. (Found by the quilt mode; same trick.)
typedef uchar16 __attribute__((aligned(1))) uchar16_u;
#define LOAD16(p) (*(__global const uchar16_u *)(p))
typedef int16 __attribute__((aligned(4))) int16_u;

// Round to nearest even and saturate, as convert_uchar16_sat_rte but faster on PoCL: after
// the clamp, adding 1.5 * 2^23 leaves the rounded integer in the low mantissa bits.
inline uchar16 to_uchar16(float16 v) { return convert_uchar16(as_uint16(clamp(v, 0.0f, 255.0f) + 12582912.0f)); }

inline void pixel(__global const uchar *restrict stack, __global const float *restrict tones, int pix, int tone,
                  float t, __global uchar *restrict o)
{
    const int ti = fast_floor(t);
    __global const uchar *p0 = stack + ((size_t)wrap_index(ti) * FRAME_PIXELS + pix) * 3;
    float r = p0[0], g = p0[1], b = p0[2];
#if INTERP
    const float f = t - (float)ti;
    __global const uchar *p1 = stack + ((size_t)wrap_index(ti + 1) * FRAME_PIXELS + pix) * 3;
    r = r + f * ((float)p1[0] - r);
    g = g + f * ((float)p1[1] - g);
    b = b + f * ((float)p1[2] - b);
#endif
    __global const float *tn = tones + tone * TONE_STRIDE;
    o[0] = convert_uchar_sat_rte(r * tn[0] + tn[48]);
    o[1] = convert_uchar_sat_rte(g * tn[1] + tn[49]);
    o[2] = convert_uchar_sat_rte(b * tn[2] + tn[50]);
}

// the bytes [lo, hi) of v to o (a run's chunk at a row's end)
#define SP1(j, c) if (lo <= j && j < hi) o[j] = v.c;
inline void store_part(uchar16 v, __global uchar *o, int lo, int hi)
{
    SP1(0, s0) SP1(1, s1) SP1(2, s2) SP1(3, s3) SP1(4, s4) SP1(5, s5) SP1(6, s6) SP1(7, s7)
    SP1(8, s8) SP1(9, s9) SP1(10, sa) SP1(11, sb) SP1(12, sc) SP1(13, sd) SP1(14, se) SP1(15, sf)
}

// 48 bytes of frame pointer p (A) merged with those of q (B) where mask m* is set
#define LOAD48(p, q, split, a0, a1, a2) do {                                            \
        a0 = LOAD16(p); a1 = LOAD16((p) + 16); a2 = LOAD16((p) + 32);                   \
        if (split < 16) {                                                               \
            a0 = select(a0, LOAD16(q), m0); a1 = select(a1, LOAD16((q) + 16), m1);      \
            a2 = select(a2, LOAD16((q) + 32), m2);                                      \
        }                                                                               \
    } while (0)

__kernel void gather(__global const uchar *restrict stack,
                     __global const int *restrict source,
                     __global const float *restrict tmap,
                     __global const float *restrict tones,
                     __global uchar *restrict out,
                     const int width, const int height,
                     const int grid_w,
                     const int tmap_w, const int tmap_h,
                     const float t0)
{
    stack += STACK_PAD;
    const int ybeg = (int)get_global_id(1) * ROWS;
    const int yend = min(ybeg + ROWS, height);
    // lane weights inside a lattice interval, twice (lanes 0-7: interval m, 8-15: m + 1)
    const float16 lane = (float16)(0.0625f, 0.1875f, 0.3125f, 0.4375f, 0.5625f, 0.6875f, 0.8125f, 0.9375f,
                                   0.0625f, 0.1875f, 0.3125f, 0.4375f, 0.5625f, 0.6875f, 0.8125f, 0.9375f);
    // pixel (lane) of each byte of the three 16-byte chunks of a run
    const uint16 c0 = (uint16)(0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4, 5);
    const uint16 c1 = (uint16)(5, 5, 6, 6, 6, 7, 7, 7, 8, 8, 8, 9, 9, 9, 10, 10);
    const uint16 c2 = (uint16)(10, 11, 11, 11, 12, 12, 12, 13, 13, 13, 14, 14, 14, 15, 15, 15);
    const char16 bi = (char16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    for (int y = ybeg; y < yend; ++y) {
        const float fy = ((float)y + 0.5f) * 0.125f - 0.5f;
        const int yi = fast_floor(fy);
        const float wy = fy - (float)yi;
        __global const float *trow0 = tmap + (size_t)clamp(yi, 0, tmap_h - 1) * tmap_w;
        __global const float *trow1 = tmap + (size_t)clamp(yi + 1, 0, tmap_h - 1) * tmap_w;
#if GRID
        const int cy = y / CELL_H;
        __global const int *srow = source + cy * grid_w;
        const int dy = (y - cy * CELL_H) * FRAME_W;
#else
        __global const int *srow = source + (size_t)y * width;
#endif
        __global uchar *orow = out + (size_t)y * width * 3;
        const int xbase = (int)get_global_id(0) * VRUN - 4;
        for (int xs = xbase; xs < xbase + VRUN && xs < width; xs += 16) {
            // pixels xs .. xs+7 lie in lattice interval m, xs+8 .. xs+15 in m + 1
            const int m = (xs - 4) >> 3;
            const int x0 = clamp(m, 0, tmap_w - 1), x1 = clamp(m + 1, 0, tmap_w - 1), x2 = clamp(m + 2, 0, tmap_w - 1);
            const float a0 = trow0[x0], a1 = trow0[x1], a2 = trow0[x2];
            const float b0 = trow1[x0], b1 = trow1[x1], b2 = trow1[x2];
            const float16 ta = (float16)((float8)a0, (float8)a1), tb = (float16)((float8)a1, (float8)a2);
            const float16 ba = (float16)((float8)b0, (float8)b1), bb = (float16)((float8)b1, (float8)b2);
            const float16 top = ta + lane * (tb - ta);
            const float16 bot = ba + lane * (bb - ba);
            const float16 t = t0 + (top + wy * (bot - top));
            // floor in vector form (convert_int16_rtn goes lane by lane in PoCL): truncate,
            // then subtract one where that rounded up (a true comparison is -1)
            const int16 tt = convert_int16(t);
            const int16 ti = tt + (convert_float16(tt) > t);
            // valid bytes of the run: [blo, bhi) (the first and last runs of a row reach past it)
            const int blo = max(-xs, 0) * 3, bhi = min(width - xs, 16) * 3;
            int pix0 = 0, tone = 0;
            bool linear = false;
            // lanes >= split read the next cell (pixb + lane); 16: none do. Lanes outside the
            // row read whatever lies there (inside the padded stack) and are not stored.
            int split = 16, pixb = 0, toneb = 0;
#if GRID
            {
                const int cx = max(xs, 0) / CELL_W;
                const int packed = srow[cx];
                pix0 = (packed & 0xFFFFFF) + dy + (xs - cx * CELL_W);
                tone = (packed >> 24) & 0xFF;
                linear = true;
                const int edge = (cx + 1) * CELL_W;          // the next cell's first pixel
                if (edge - xs < 16 && edge < width) {
                    split = edge - xs;
                    const int pb = srow[cx + 1];
                    pixb = (pb & 0xFFFFFF) + dy - split;
                    toneb = (pb >> 24) & 0xFF;
#if CELL_W < 16
                    linear = split + CELL_W >= 16 || edge + CELL_W >= width;   // else a third cell: per pixel
#endif
                }
            }
#else
            if (xs >= 0 && xs + 16 <= width) {
                const int16 pk = *(__global const int16_u *)(srow + xs);
                const int16 step = (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
                pix0 = pk.s0 & 0xFFFFFF;
                tone = (pk.s0 >> 24) & 0xFF;
                linear = all((pk - pk.s0) == step);
            }
#endif
            // t is linear on lanes 0-7 and on 8-15: its extremes sit at lanes 0, 7, 8, 15
            const int lo = min(min(ti.s0, ti.s7), min(ti.s8, ti.sf));
            const int hi = max(max(ti.s0, ti.s7), max(ti.s8, ti.sf));
            if (linear && hi - lo <= 1) {
                const char16 m0 = bi >= (char)(3 * min(split, 16));          // bytes from the next cell
                const char16 m1 = bi >= (char)(3 * min(split, 16) - 16);
                const char16 m2 = bi >= (char)(3 * min(split, 16) - 32);
                // lanes at frame lo blend (F[lo], F[lo+1]); lanes at lo+1 blend (F[lo+1], F[lo+2])
                const size_t f0 = (size_t)wrap_index(lo) * FRAME_PIXELS, f1 = (size_t)wrap_index(lo + 1) * FRAME_PIXELS;
                uchar16 u0, u1, u2, w0, w1, w2;
                LOAD48(stack + (f0 + pix0) * 3, stack + (f0 + pixb) * 3, split, u0, u1, u2);
                LOAD48(stack + (f1 + pix0) * 3, stack + (f1 + pixb) * 3, split, w0, w1, w2);
                float16 va0 = convert_float16(u0), va1 = convert_float16(u1), va2 = convert_float16(u2);
                float16 vb0 = convert_float16(w0), vb1 = convert_float16(w1), vb2 = convert_float16(w2);
                if (hi > lo) {
                    const size_t f2 = (size_t)wrap_index(lo + 2) * FRAME_PIXELS;
                    uchar16 e0, e1, e2;
                    LOAD48(stack + (f2 + pix0) * 3, stack + (f2 + pixb) * 3, split, e0, e1, e2);
                    const float16 sel = convert_float16(ti - lo);            // 0 or 1 per lane
                    const float16 s0 = shuffle(sel, c0), s1 = shuffle(sel, c1), s2 = shuffle(sel, c2);
                    va0 = va0 + s0 * (vb0 - va0);                             // F[ti]
                    va1 = va1 + s1 * (vb1 - va1);
                    va2 = va2 + s2 * (vb2 - va2);
                    vb0 = vb0 + s0 * (convert_float16(e0) - vb0);             // F[ti + 1]
                    vb1 = vb1 + s1 * (convert_float16(e1) - vb1);
                    vb2 = vb2 + s2 * (convert_float16(e2) - vb2);
                }
#if INTERP
                const float16 f = t - convert_float16(ti);
                va0 = va0 + shuffle(f, c0) * (vb0 - va0);
                va1 = va1 + shuffle(f, c1) * (vb1 - va1);
                va2 = va2 + shuffle(f, c2) * (vb2 - va2);
#endif
                __global const float *tn = tones + tone * TONE_STRIDE;
                float16 g0 = vload16(0, tn), g1 = vload16(1, tn), g2 = vload16(2, tn);
                float16 o0 = vload16(3, tn), o1 = vload16(4, tn), o2 = vload16(5, tn);
                if (split < 16 && toneb != tone) {
                    __global const float *tb = tones + toneb * TONE_STRIDE;
                    const int16 n0 = convert_int16(m0), n1 = convert_int16(m1), n2 = convert_int16(m2);
                    g0 = select(g0, vload16(0, tb), n0);
                    g1 = select(g1, vload16(1, tb), n1);
                    g2 = select(g2, vload16(2, tb), n2);
                    o0 = select(o0, vload16(3, tb), n0);
                    o1 = select(o1, vload16(4, tb), n1);
                    o2 = select(o2, vload16(5, tb), n2);
                }
                __global uchar *o = orow + xs * 3;
                const uchar16 r0 = to_uchar16(va0 * g0 + o0), r1 = to_uchar16(va1 * g1 + o1), r2 = to_uchar16(va2 * g2 + o2);
                if (blo == 0 && bhi == 48) {
                    *(__global uchar16_u *)o = r0;
                    *(__global uchar16_u *)(o + 16) = r1;
                    *(__global uchar16_u *)(o + 32) = r2;
                } else {
                    store_part(r0, o, blo, bhi);
                    store_part(r1, o + 16, blo - 16, bhi - 16);
                    store_part(r2, o + 32, blo - 32, bhi - 32);
                }
            } else {
                float tl[16];
                vstore16(t, 0, tl);
                for (int j = 0; j < 16; ++j) {
                    const int x = xs + j;
                    if (x < 0 || x >= width)
                        continue;
#if GRID
                    const int cx = x / CELL_W;
                    const int packed = srow[cx];
                    const int pix = (packed & 0xFFFFFF) + dy + (x - cx * CELL_W);
#else
                    const int packed = srow[x];
                    const int pix = packed & 0xFFFFFF;
#endif
                    pixel(stack, tones, pix, (packed >> 24) & 0xFF, tl[j], orow + x * 3);
                }
            }
        }
    }
}

#else
// One work-item renders RUN consecutive pixels of one row (global size (ceil(W/RUN), H)):
// on CPU devices a loop per work-item beats one work-item per pixel by a wide margin.
__kernel void gather(__global const uchar *restrict stack,
                     __global const int *restrict source,
                     __global const float *restrict tmap,
                     __global const float *restrict tones,   // (ntones, TONE_STRIDE): see the host
                     __global uchar *restrict out,
                     const int width, const int height,
                     const int grid_w,
                     const int tmap_w, const int tmap_h,
                     const float t0)
{
    const int y = get_global_id(1);
    const int xstart = get_global_id(0) * RUN;
    if (y >= height)
        return;
    stack += STACK_PAD;
    const int xend = min(xstart + RUN, width);
#if TSTEP > 1
    // Vertical part of the bilinear time lookup is shared by the whole run.
    const float fy = ((float)y + 0.5f) * (1.0f / TSTEP) - 0.5f;
    const int yi = fast_floor(fy);
    const float wy = fy - (float)yi;
    __global const float *trow0 = tmap + (size_t)clamp(yi, 0, tmap_h - 1) * tmap_w;
    __global const float *trow1 = tmap + (size_t)clamp(yi + 1, 0, tmap_h - 1) * tmap_w;
#else
    __global const float *trow = tmap + (size_t)y * tmap_w;
#endif
#if GRID
    const int cy = y / CELL_H;
    __global const int *srow = source + cy * grid_w;
    const int dy = (y - cy * CELL_H) * FRAME_W;
#else
    __global const int *srow = source + (size_t)y * width;
#endif
    __global uchar *o = out + ((size_t)y * width + xstart) * 3;
    for (int x = xstart; x < xend; ++x, o += 3) {
#if GRID
        const int cx = x / CELL_W;
        const int packed = srow[cx];
        const int pix = (packed & 0xFFFFFF) + dy + (x - cx * CELL_W);
#else
        const int packed = srow[x];
        const int pix = packed & 0xFFFFFF;
#endif
#if TSTEP > 1
        const float fx = ((float)x + 0.5f) * (1.0f / TSTEP) - 0.5f;
        const int xi = fast_floor(fx);
        const float wx = fx - (float)xi;
        const int x0 = clamp(xi, 0, tmap_w - 1), x1 = clamp(xi + 1, 0, tmap_w - 1);
        const float top = trow0[x0] + wx * (trow0[x1] - trow0[x0]);
        const float bot = trow1[x0] + wx * (trow1[x1] - trow1[x0]);
        const float t = t0 + (top + wy * (bot - top));
#else
        const float t = t0 + trow[x];
#endif
        const int ti = fast_floor(t);
        // Scalar channels on purpose: PoCL's float3/vload3 code is an order of magnitude slower.
        __global const uchar *p0 = stack + ((size_t)wrap_index(ti) * FRAME_PIXELS + pix) * 3;
        float r = p0[0], g = p0[1], b = p0[2];
#if INTERP
        const float f = t - (float)ti;
        __global const uchar *p1 = stack + ((size_t)wrap_index(ti + 1) * FRAME_PIXELS + pix) * 3;
        r = r + f * ((float)p1[0] - r);
        g = g + f * ((float)p1[1] - g);
        b = b + f * ((float)p1[2] - b);
#endif
        __global const float *tn = tones + ((packed >> 24) & 0xFF) * TONE_STRIDE;
        o[0] = convert_uchar_sat_rte(r * tn[0] + tn[48]);
        o[1] = convert_uchar_sat_rte(g * tn[1] + tn[49]);
        o[2] = convert_uchar_sat_rte(b * tn[2] + tn[50]);
    }
}

#endif

// Separable Gaussian smoothing of a float map, edges clamped; weights holds 2 * radius + 1
// taps. smooth_x runs along rows, smooth_y along columns (two kernel objects, so each
// keeps its own arguments).
__kernel void smooth_x(__global const float *restrict src,
                       __global float *restrict dst,
                       __constant float *restrict weights,
                       const int w, const int h, const int radius)
{
    const int x = get_global_id(0);
    const int y = get_global_id(1);
    if (x >= w || y >= h)
        return;
    __global const float *row = src + (size_t)y * w;
    float acc = 0.0f;
    for (int k = -radius; k <= radius; ++k)
        acc += weights[k + radius] * row[clamp(x + k, 0, w - 1)];
    dst[(size_t)y * w + x] = acc;
}

__kernel void smooth_y(__global const float *restrict src,
                       __global float *restrict dst,
                       __constant float *restrict weights,
                       const int w, const int h, const int radius)
{
    const int x = get_global_id(0);
    const int y = get_global_id(1);
    if (x >= w || y >= h)
        return;
    float acc = 0.0f;
    for (int k = -radius; k <= radius; ++k)
        acc += weights[k + radius] * src[(size_t)clamp(y + k, 0, h - 1) * w + x];
    dst[(size_t)y * w + x] = acc;
}
