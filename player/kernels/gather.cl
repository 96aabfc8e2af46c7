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
// Vectorised variant for a time lattice of step 8. Work-item k renders the 64 pixels
// [64k - 4, 64k + 60) of one row in eight runs of 8 aligned to the lattice, so that in a run
// the time is linear in x (one lattice interval) and is computed as a float8. When a run
// reads 8 contiguous source pixels of one tone (one tile cell) whose frame indices span at
// most two neighbours, it moves 24 bytes per frame with vector loads (three frames when
// the run crosses a frame boundary) and blends in float16 + float8; otherwise it falls
// back to the per-pixel path.
// Same formulas as the scalar kernel and the numpy reference.
#define VRUN 64

// PoCL's vload16/vstore16 of uchar move byte by byte; an under-aligned vector type gives one
// unaligned 16-byte (8-byte) access. (Found by the quilt mode; same trick.)
typedef uchar16 __attribute__((aligned(1))) uchar16_u;
typedef uchar8 __attribute__((aligned(1))) uchar8_u;
#define LOAD16(p) (*(__global const uchar16_u *)(p))
#define LOAD8(p) (*(__global const uchar8_u *)(p))
typedef int8 __attribute__((aligned(4))) int8_u;

// Round to nearest even and saturate, as convert_uchar*_sat_rte but faster on PoCL: after the
// clamp, adding 1.5 * 2^23 leaves the rounded integer in the low mantissa bits.
inline uchar16 to_uchar16(float16 v) { return convert_uchar16(as_uint16(clamp(v, 0.0f, 255.0f) + 12582912.0f)); }
inline uchar8 to_uchar8(float8 v) { return convert_uchar8(as_uint8(clamp(v, 0.0f, 255.0f) + 12582912.0f)); }

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
    __global const float *tn = tones + tone * 6;
    o[0] = convert_uchar_sat_rte(r * tn[0] + tn[3]);
    o[1] = convert_uchar_sat_rte(g * tn[1] + tn[4]);
    o[2] = convert_uchar_sat_rte(b * tn[2] + tn[5]);
}

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
    const int y = get_global_id(1);
    if (y >= height)
        return;
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
    const float8 lane = (float8)(0.0625f, 0.1875f, 0.3125f, 0.4375f, 0.5625f, 0.6875f, 0.8125f, 0.9375f);
    const int xbase = (int)get_global_id(0) * VRUN - 4;
    for (int xs = xbase; xs < xbase + VRUN && xs < width; xs += 8) {
        // pixels xs .. xs+7 lie in lattice interval m: fx = m + (j + 0.5) / 8
        const int m = (xs - 4) >> 3;
        const int x0 = clamp(m, 0, tmap_w - 1), x1 = clamp(m + 1, 0, tmap_w - 1);
        const float a = trow0[x0], b = trow0[x1], c = trow1[x0], d = trow1[x1];
        const float8 top = a + lane * (b - a);
        const float8 bot = c + lane * (d - c);
        const float8 t = t0 + (top + wy * (bot - top));
        const int8 ti = convert_int8_rtn(t);
        const bool full = xs >= 0 && xs + 8 <= width;
        int pix0 = 0, tone = 0;
        bool contiguous = false;
        if (full) {
#if GRID
            const int cx = xs / CELL_W;
            if ((xs + 7) / CELL_W == cx) {
                const int packed = srow[cx];
                pix0 = (packed & 0xFFFFFF) + dy + (xs - cx * CELL_W);
                tone = (packed >> 24) & 0xFF;
                contiguous = true;
            }
#else
            const int8 pk = *(__global const int8_u *)(srow + xs);
            const int8 step = (int8)(0, 1, 2, 3, 4, 5, 6, 7);
            pix0 = pk.s0 & 0xFFFFFF;
            tone = (pk.s0 >> 24) & 0xFF;
            contiguous = all((pk - pk.s0) == step);
#endif
        }
        const int lo = min(ti.s0, ti.s7), hi = max(ti.s0, ti.s7);   // t is monotone in a run
        if (contiguous && hi - lo <= 1) {
            // lanes at frame lo blend (F[lo], F[lo+1]); lanes at lo+1 blend (F[lo+1], F[lo+2])
            __global const uchar *p0 = stack + ((size_t)wrap_index(lo) * FRAME_PIXELS + pix0) * 3;
            __global const uchar *p1 = stack + ((size_t)wrap_index(lo + 1) * FRAME_PIXELS + pix0) * 3;
            float16 va = convert_float16(LOAD16(p0));
            float8 vb = convert_float8(LOAD8(p0 + 16));
            const uint16 la = (uint16)(0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4, 5);
            const uint8 lb = (uint8)(5, 5, 6, 6, 6, 7, 7, 7);
            float16 wa = convert_float16(LOAD16(p1));
            float8 wb = convert_float8(LOAD8(p1 + 16));
            if (hi > lo) {
                __global const uchar *p2 = stack + ((size_t)wrap_index(lo + 2) * FRAME_PIXELS + pix0) * 3;
                const float8 sel = convert_float8(ti - lo);             // 0 or 1 per lane
                const float16 sa = shuffle(sel, la);
                const float8 sb = shuffle(sel, lb);
                va = va + sa * (wa - va);                                // F[ti]
                vb = vb + sb * (wb - vb);
                wa = wa + sa * (convert_float16(LOAD16(p2)) - wa);   // F[ti + 1]
                wb = wb + sb * (convert_float8(LOAD8(p2 + 16)) - wb);
            }
#if INTERP
            const float8 f = t - convert_float8(ti);
            va = va + shuffle(f, la) * (wa - va);
            vb = vb + shuffle(f, lb) * (wb - vb);
#endif
            __global const float *tn = tones + tone * 6;
            const float4 g = (float4)(tn[0], tn[1], tn[2], 0.0f);
            const float4 off = (float4)(tn[3], tn[4], tn[5], 0.0f);
            const uint16 ca = (uint16)(0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0);
            const uint8 cb = (uint8)(1, 2, 0, 1, 2, 0, 1, 2);
            va = va * shuffle(g, ca) + shuffle(off, ca);
            vb = vb * shuffle(g, cb) + shuffle(off, cb);
            __global uchar *o = orow + xs * 3;
            *(__global uchar16_u *)o = to_uchar16(va);
            *(__global uchar8_u *)(o + 16) = to_uchar8(vb);
        } else {
            float tl[8];
            vstore8(t, 0, tl);
            for (int j = 0; j < 8; ++j) {
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

#else
// One work-item renders RUN consecutive pixels of one row (global size (ceil(W/RUN), H)):
// on CPU devices a loop per work-item beats one work-item per pixel by a wide margin.
__kernel void gather(__global const uchar *restrict stack,
                     __global const int *restrict source,
                     __global const float *restrict tmap,
                     __global const float *restrict tones,   // (ntones, 6): gain rgb, offset rgb
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
        __global const float *tn = tones + ((packed >> 24) & 0xFF) * 6;
        o[0] = convert_uchar_sat_rte(r * tn[0] + tn[3]);
        o[1] = convert_uchar_sat_rte(g * tn[1] + tn[4]);
        o[2] = convert_uchar_sat_rte(b * tn[2] + tn[5]);
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
