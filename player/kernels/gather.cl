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
