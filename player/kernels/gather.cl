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
// WRAP (0 loop, 1 clamp, 2 ping-pong), INTERP (1: linear in time, 0: nearest earlier
// frame), TSTEP.

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

inline float sample_time(__global const float *restrict tmap, int tw, int th, int y, int x)
{
#if TSTEP == 1
    return tmap[(size_t)y * tw + x];
#else
    const float fy = ((float)y + 0.5f) * (1.0f / TSTEP) - 0.5f;
    const float fx = ((float)x + 0.5f) * (1.0f / TSTEP) - 0.5f;
    const float y0f = floor(fy), x0f = floor(fx);
    const float wy = fy - y0f, wx = fx - x0f;
    const int y0 = clamp((int)y0f, 0, th - 1), y1 = clamp((int)y0f + 1, 0, th - 1);
    const int x0 = clamp((int)x0f, 0, tw - 1), x1 = clamp((int)x0f + 1, 0, tw - 1);
    const float a = tmap[(size_t)y0 * tw + x0], b = tmap[(size_t)y0 * tw + x1];
    const float c = tmap[(size_t)y1 * tw + x0], d = tmap[(size_t)y1 * tw + x1];
    const float top = a + wx * (b - a);
    const float bot = c + wx * (d - c);
    return top + wy * (bot - top);
#endif
}

__kernel void gather(__global const uchar *restrict stack,
                     __global const int *restrict source,
                     __global const float *restrict tmap,
                     __global const float *restrict tones,   // (ntones, 6): gain rgb, offset rgb
                     __global uchar *restrict out,
                     const int width, const int height,
                     const int cell_h, const int cell_w, const int grid_w,
                     const int tmap_w, const int tmap_h,
                     const float t0)
{
    const int x = get_global_id(0);
    const int y = get_global_id(1);
    if (x >= width || y >= height)
        return;
#if GRID
    const int cy = y / cell_h, cx = x / cell_w;
    const int packed = source[cy * grid_w + cx];
    const int pix = (packed & 0xFFFFFF) + (y - cy * cell_h) * FRAME_W + (x - cx * cell_w);
#else
    const int packed = source[(size_t)y * width + x];
    const int pix = packed & 0xFFFFFF;
#endif
    const int tone = (packed >> 24) & 0xFF;
    const float t = t0 + sample_time(tmap, tmap_w, tmap_h, y, x);
    const float tf = floor(t);
    const int i0 = wrap_index((int)tf);
    float3 v = convert_float3(vload3(0, stack + ((size_t)i0 * FRAME_PIXELS + pix) * 3));
#if INTERP
    const float f = t - tf;
    const int i1 = wrap_index((int)tf + 1);
    const float3 v1 = convert_float3(vload3(0, stack + ((size_t)i1 * FRAME_PIXELS + pix) * 3));
    v = v + f * (v1 - v);
#endif
    __global const float *tn = tones + tone * 6;
    v = v * (float3)(tn[0], tn[1], tn[2]) + (float3)(tn[3], tn[4], tn[5]);
    vstore3(convert_uchar3_sat_rte(v), 0, out + ((size_t)y * width + x) * 3);
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
