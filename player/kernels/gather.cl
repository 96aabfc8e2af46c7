// Shared gather machinery (mode tiles, and any mode that copies stored pixels): every output
// pixel is read from a stack of stored frames at a per-pixel source pixel and a per-pixel
// time, blended linearly between the two neighbouring stored frames and colour-toned.
//
// A packed source entry is (tone << 24) | (y * FRAME_W + x): a pixel of one stored frame
// plus the index of its tone. The source is either a per-pixel map (GRID == 0, one entry
// per output pixel) or a grid of cells (GRID == 1, one entry per cell naming the cell's
// top-left pixel; the pixel at (dy, dx) inside the cell reads origin + dy * FRAME_W + dx).
//
// Time, in integers after one rounding per map sample (the numpy reference computes the
// same integers): the map is m = m0 + fade (m1 - m0) (two maps, faded on the fly), sample
// (i, j) in 4080ths (255 * 16) of a frame past base = floor(t0):
// Q = floor((f0 + m[i][j]) * 4080 + 0.5), f0 = t0 - base, float32 without contraction.
// The map is sampled bilinearly at a step of s = TSTEP output pixels, in halves of a step:
// n = 2x + 1 - s = 2s xi + kx (0 <= kx < 2s), likewise yi, ky; indices clamped to the map.
// H = floor((Q[yi][xi] (2s - kx) + Q[yi][xi+1] kx + 16s) / 32s) on map rows yi and yi + 1
// (255ths), u = floor((H_top (2s - ky) + H_bot ky + s) / 2s) (s = 1: u = floor((Q + 8) / 16)):
// the pixel's time in 255ths of a frame past base. Frame i = base + floor(u / 255), weight
// w = u mod 255.
//
// Blend and tone in fixed point: v = (255 - w) (a - 128) + w (b - 128) for the channel
// values a = F[wrap(i)], b = F[wrap(i + 1)] (v = 255 (value - 128), signed 16
// bit); tone gain G = round(gain 2^17 / 255), offset O = round(2 (128 gain + offset)) + 1:
// out = clamp((((v G) >> 16) + O) >> 1, 0, 255) (arithmetic shifts), which is
// round(value * gain + offset) up to the quantisation. Every intermediate fits 16 bits for
// gains up to 63 and offsets within 255 (so a 16-bit multiply-add can blend and tone).
//
// This file is portable OpenCL C 1.2 and holds the default kernel, gather. The x86 variant
// variants/gather_wide.cl is appended to it on devices where it passed the self-test.
//
// Defines: FRAME_W, FRAME_PIXELS (stored frame width, width * height), NFRAMES, GRID,
// CELL_H, CELL_W (cell size of the grid; compile-time so the divisions become multiplies),
// WRAP (0 loop, 1 clamp, 2 ping-pong), INTERP (1: linear in time, 0: nearest earlier
// frame), TSTEP, RUN (pixels per work-item), STACK_PAD, STACK_SIGNED (1: the stack holds
// value ^ 0x80, as the variant reads it), TONE_STRIDE, TONE_OB (shorts per tone row, and
// where its offsets start), PIXEL_BYTES, R_AT, G_AT, B_AT, A_AT (bytes of an output pixel and
// where each colour, and alpha (255; -1: none), goes); the variant also takes BANDS.

#pragma OPENCL FP_CONTRACT OFF      // the time samples round as the numpy reference's float32

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

// floor(a / b) for b > 0
inline int floor_div(int a, int b)
{
    const int q = a / b;
    return q - (q * b > a);
}

inline long floor_divl(long a, long b)
{
    const long q = a / b;
    return q - (q * b > a);
}

// map sample k faded toward its target (header)
inline float faded(__global const float *m0, __global const float *m1, float fade, size_t k)
{
    return m0[k] + fade * (m1[k] - m0[k]);
}

// a map sample in 4080ths of a frame past base (header)
inline int time_q(float f0, __global const float *m0, __global const float *m1, float fade, size_t k)
{
    return fast_floor((f0 + faded(m0, m1, fade, k)) * 4080.0f + 0.5f);
}

// The arguments of kernel gather (both variants below); tones is (ntones, TONE_STRIDE): see the host.
#define GATHER_PARAMS __global const uchar *restrict stack, __global const int *restrict source,            \
                      __global const float *restrict tmap, __global const float *restrict tmap1,          \
                      __global const short *restrict tones,                                                \
                      __global uchar *restrict out, const int width, const int height, const int grid_w,   \
                      const int tmap_w, const int tmap_h, const float t0, const float fade

// a stored byte as value - 128 (STACK_SIGNED: the stack holds value ^ 0x80, a signed byte)
#if STACK_SIGNED
#define SVAL(s) ((int)(char)(s))
#else
#define SVAL(s) ((int)(s) - 128)
#endif

// one channel: blended value v (255 (value - 128)), tone gain g and offset o as in the header
inline uchar tone1(int v, int g, int o)
{
    return (uchar)clamp((((v * g) >> 16) + o) >> 1, 0, 255);
}

// the stored pixel that output pixel x reads, from its row of the source (a row of cells, dy
// the row's offset inside them; or a row of the per-pixel map); *packed gets the entry (its tone)
inline int source_pixel(__global const int *srow, int dy, int x, int *packed)
{
#if GRID
    const int cx = x / CELL_W;
    *packed = srow[cx];
    return (*packed & 0xFFFFFF) + dy + (x - cx * CELL_W);
#else
    *packed = srow[x];
    return *packed & 0xFFFFFF;
#endif
}

// one output pixel from source pixel pix with tone: frame ti, weight w (255ths of the next)
inline void pixel(__global const uchar *restrict stack, __global const short *restrict tones, int pix, int tone,
                  int ti, int w, __global uchar *restrict o)
{
    __global const uchar *p0 = stack + ((size_t)wrap_index(ti) * FRAME_PIXELS + pix) * 3;
#if INTERP
    __global const uchar *p1 = stack + ((size_t)wrap_index(ti + 1) * FRAME_PIXELS + pix) * 3;
#else
    w = 0;
    __global const uchar *p1 = p0;
#endif
    __global const short *tn = tones + tone * TONE_STRIDE;
    // scalar channels on purpose: PoCL's 3-vectors are an order of magnitude slower
    put1(tone1((255 - w) * SVAL(p0[0]) + w * SVAL(p1[0]), tn[0], tn[TONE_OB]),
         tone1((255 - w) * SVAL(p0[1]) + w * SVAL(p1[1]), tn[1], tn[TONE_OB + 1]),
         tone1((255 - w) * SVAL(p0[2]) + w * SVAL(p1[2]), tn[2], tn[TONE_OB + 2]), o);
}


// One work-item renders RUN consecutive pixels of one row (global size (ceil(W/RUN), H)):
// on CPU devices a loop per work-item beats one work-item per pixel by a wide margin.
__kernel void gather(GATHER_PARAMS)
{
    const int y = get_global_id(1);
    const int xstart = get_global_id(0) * RUN;
    if (y >= height)
        return;
    stack += STACK_PAD;
    const int xend = min(xstart + RUN, width);
    const int base = fast_floor(t0);
    const float f0 = t0 - (float)base;
#if TSTEP > 1
    const int ny = 2 * y + 1 - TSTEP, yi = floor_div(ny, 2 * TSTEP), ky = ny - 2 * TSTEP * yi;
    const size_t row0 = (size_t)clamp(yi, 0, tmap_h - 1) * tmap_w, row1 = (size_t)clamp(yi + 1, 0, tmap_h - 1) * tmap_w;
#else
    const size_t row0 = (size_t)y * tmap_w;
#endif
#if GRID
    const int cy = y / CELL_H;
    __global const int *srow = source + cy * grid_w;
    const int dy = (y - cy * CELL_H) * FRAME_W;
#else
    __global const int *srow = source + (size_t)y * width;
    const int dy = 0;
#endif
    for (int x = xstart; x < xend; ++x) {
        int packed;
        const int pix = source_pixel(srow, dy, x, &packed);
        // the pixel's time u in 255ths past base (header), in 64 bits: any step
#if TSTEP > 1
        const int nx = 2 * x + 1 - TSTEP, xi = floor_div(nx, 2 * TSTEP), kx = nx - 2 * TSTEP * xi;
        const int c0 = clamp(xi, 0, tmap_w - 1), c1 = clamp(xi + 1, 0, tmap_w - 1);
        const long ht = floor_divl((long)time_q(f0, tmap, tmap1, fade, row0 + c0) * (2 * TSTEP - kx)
                                   + (long)time_q(f0, tmap, tmap1, fade, row0 + c1) * kx + 16 * TSTEP, 32 * TSTEP);
        const long hb = floor_divl((long)time_q(f0, tmap, tmap1, fade, row1 + c0) * (2 * TSTEP - kx)
                                   + (long)time_q(f0, tmap, tmap1, fade, row1 + c1) * kx + 16 * TSTEP, 32 * TSTEP);
        const int u = (int)floor_divl(ht * (2 * TSTEP - ky) + hb * ky + TSTEP, 2 * TSTEP);
#else
        const int u = floor_div(time_q(f0, tmap, tmap1, fade, row0 + x) + 8, 16);
#endif
        const int fi = floor_div(u, 255);
        pixel(stack, tones, pix, (packed >> 24) & 0xFF, base + fi, u - 255 * fi,
              out + ((size_t)y * width + x) * PIXEL_BYTES);
    }
}


// Separable Gaussian smoothing of a w x h float map, edges clamped; weights holds 2 * radius + 1
// taps. along = 0 smooths along rows, 1 along columns (the host fetches two kernel objects,
// so each keeps its own arguments).
__kernel void smooth(__global const float *restrict src,
                     __global float *restrict dst,
                     __constant float *restrict weights,
                     const int w, const int h, const int radius, const int along)
{
    const int x = get_global_id(0);
    const int y = get_global_id(1);
    if (x >= w || y >= h)
        return;
    const int n = along ? h : w, i = along ? y : x;
    const size_t step = along ? (size_t)w : 1;
    __global const float *line = src + (along ? (size_t)x : (size_t)y * w);
    float acc = 0.0f;
    for (int k = -radius; k <= radius; ++k)
        acc += weights[k + radius] * line[(size_t)clamp(i + k, 0, n - 1) * step];
    dst[(size_t)y * w + x] = acc;
}
