// Mode evolve (time-varying textures): the gather of gather.cl extended with a per-pixel
// time that is not an offset but a *warp*: local time tau = t * rate(y, x) (the rate map M),
// folded by the end mode, then passed through the monotone time warp of the pixel's block
// (the jitter f_b, a piecewise-linear table with one knot per source frame). Pixels in
// the cross-fade band of a quilt cut blend a second source (with its own block's warp).
//
// Conventions follow gather.cl: a source entry is a pixel index y * w + x of one stored
// frame in the low 24 bits; here the high 8 bits hold the weight of the second source in
// 1/256 (0: no blend). One work-item renders RUN consecutive pixels of one row; channels
// are scalar (PoCL's float3 is slow).
//
// Defines: FRAME_PIXELS, NFRAMES, KNOTS (knots per block warp, NFRAMES + 1), INTERP,
// RATE (1: per-pixel rate map and per-pixel warps; 0: uniform rate, per-block source
// times btime precomputed on the host each frame), BLEND (1: cross-fade band), GAIN (1: per-pixel RGB gain),
// LABEL16 (1: labels stored as ushort), RUN, END (0 hold, 1 loop, 2 ping-pong; the player
// builds all three, so the end control switches kernels without a rebuild).

#if LABEL16
typedef ushort label_t;
#else
typedef uint label_t;
#endif

inline int fast_floor(float v)
{
    const int i = (int)v;
    return i - (int)((float)i > v);
}

// Local time folded into the source timeline: hold [0, N-1], loop [0, N), ping-pong [0, N-1].
// The end mode is a define (each of the three is built at player construction): a runtime
// choice here, even as selects, costs PoCL 1.7x (a branch 2.7x).
inline float fold_time(float tau)
{
#if END == 0
    return clamp(tau, 0.0f, (float)(NFRAMES - 1));
#elif END == 1
    const float n = (float)NFRAMES;
    return clamp(tau - n * (float)fast_floor(tau * (1.0f / (float)NFRAMES)), 0.0f, n);
#elif NFRAMES == 1
    return 0.0f;
#else
    const float p = (float)(2 * (NFRAMES - 1));
    const float m = clamp(tau - p * (float)fast_floor(tau * (1.0f / (float)(2 * (NFRAMES - 1)))), 0.0f, p);
    return m <= (float)(NFRAMES - 1) ? m : p - m;
#endif
}

// Source times lie in [0, NFRAMES] (the warps are clamped), so i is in [0, NFRAMES + 1]:
// loop wraps the frame after the last to the first; hold and ping-pong clamp.
inline int frame_index(int i)
{
#if END == 1
    return i >= NFRAMES ? i - NFRAMES : i;
#else
    return min(i, NFRAMES - 1);
#endif
}

inline float warp_time(__global const float *restrict warp, uint block, float tau)
{
    int k = fast_floor(tau);
    k = clamp(k, 0, KNOTS - 2);
    const float fr = tau - (float)k;
    __global const float *w = warp + (size_t)block * KNOTS + k;
    return w[0] + fr * (w[1] - w[0]);
}

inline void sample(__global const uchar *restrict stack, uint pix, float s,
                   float *r, float *g, float *b)
{
    const int si = fast_floor(s);
    __global const uchar *p0 = stack + ((size_t)frame_index(si) * FRAME_PIXELS + pix) * 3;
    float vr = p0[0], vg = p0[1], vb = p0[2];
#if INTERP
    const float f = s - (float)si;
    __global const uchar *p1 = stack + ((size_t)frame_index(si + 1) * FRAME_PIXELS + pix) * 3;
    vr = vr + f * ((float)p1[0] - vr);
    vg = vg + f * ((float)p1[1] - vg);
    vb = vb + f * ((float)p1[2] - vb);
#endif
    *r = vr; *g = vg; *b = vb;
}

__kernel void evolve(__global const uchar *restrict stack,
                     __global const uint *restrict source,
                     __global const label_t *restrict labels,
                     __global const uint *restrict source2,
                     __global const label_t *restrict labels2,
                     __global const float *restrict rate,
                     __global const float *restrict warp,
                     __global const float *restrict btime,
                     __global const float *restrict gain,
                     __global uchar *restrict out,
                     const int width, const int height,
                     const float t)
{
    const int y = get_global_id(1);
    const int xstart = get_global_id(0) * RUN;
    if (y >= height)
        return;
    const int xend = min(xstart + RUN, width);
    const size_t row = (size_t)y * width;
    for (int x = xstart; x < xend; ++x) {
        const size_t i = row + x;
#if RATE
        const float tau = fold_time(t * rate[i]);
#define SOURCE_TIME(lab) warp_time(warp, (lab), tau)
#else
        // Uniform rate: every pixel of a block shares one source time, computed on the host.
#define SOURCE_TIME(lab) btime[lab]
#endif
        const uint packed = source[i];
        float r, g, b;
        sample(stack, packed & 0xFFFFFF, SOURCE_TIME(labels[i]), &r, &g, &b);
#if BLEND
        // Branch-free: outside the band the weight is 0 and the second source a cached
        // dummy; on CPU devices this is ~1.6x faster than skipping it with a branch.
        const uint wq = packed >> 24;
        {
            float r2, g2, b2;
            sample(stack, source2[i] & 0xFFFFFF, SOURCE_TIME(labels2[i]), &r2, &g2, &b2);
            const float a = (float)wq * (1.0f / 256.0f);
            r = r + a * (r2 - r);
            g = g + a * (g2 - g);
            b = b + a * (b2 - b);
        }
#endif
#if GAIN
        r *= gain[3 * i];
        g *= gain[3 * i + 1];
        b *= gain[3 * i + 2];
#endif
        __global uchar *o = out + 3 * i;
        o[0] = convert_uchar_sat_rte(r);
        o[1] = convert_uchar_sat_rte(g);
        o[2] = convert_uchar_sat_rte(b);
    }
}
