// Mode evolve (time-varying textures): frame t gathered from the stored source frames
// through the quilt, at a per-pixel source time: local time tau = t * rate(y, x) (the rate
// map M), folded by the end mode, then passed through the monotone time warp of the
// pixel's block (the jitter f_b, a piecewise-linear table with one knot per source frame).
// Pixels in the cross-fade band of a quilt cut blend a second source (with its own block's
// warp).
//
// Runs instead of a per-pixel gather. The player cuts every output row, once at open,
// into runs: segments whose pixels read at most two *streams*, a stream being one block's
// source pixels at a constant offset (source pixel = x + offset, so the run's source is a
// contiguous run of a source frame row). A plain run reads one stream (A); a blend run (a
// cross-fade band, on both sides of the cut) reads two (A and B) and, per output byte, a
// code: the weight of the second source in 1/256 (bits 0-8) and whether the pixel's
// primary source is B (bit 9). Within a run the stream times are constant unless the rate
// map varies along it, so a work-item copies or blends whole runs as byte streams (colour
// channels are just bytes: every operation is per byte) with 16-byte vector loads and
// stores; the last chunk of a run is aligned to its end (it recomputes a few bytes with
// the same values) so nothing outside the run is touched. Runs shorter than 16 bytes go
// byte by byte, and runs along which the rate map varies pixel by pixel.
//
// Arithmetic per byte is that of the numpy reference, in float32: v = v0 + f (v1 - v0)
// per source, v = first + a (second - first) for a blend, v *= gain, rounded to nearest
// even and saturated.
//
// Defines: FRAME_BYTES (bytes of one stored frame), NFRAMES, KNOTS (knots per block warp,
// NFRAMES + 1), INTERP, RATE (1: rate map, per-run rates (negative: varies along the run)
// and per-pixel rates; 0: uniform rate, per-block frames and fractions bframe computed
// on the host each frame), GAIN (per-byte gain), END (0 hold, 1 loop, 2 ping-pong; the player
// builds all variants at open, so the end control switches kernels without a rebuild).
//
// Run tables: runs[r] = (first output pixel, pixel of stream A at it, block of A, length |
// blend << 31 | spill << 30), runs_b[r] = (pixel of stream B at the first output pixel, block of B);
// row_start[y] .. row_start[y + 1] are the runs of output row y (one work-item per row).

#define BLEND_FLAG 0x80000000u
#define SPILL_FLAG 0x40000000u

inline int fast_floor(float v)
{
    const int i = (int)v;
    return i - (int)((float)i > v);
}

// Local time folded into the source timeline: hold [0, N-1], loop [0, N), ping-pong [0, N-1].
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

// The two frames a source time reads (byte offset pixb inside a frame) and the fraction.
typedef struct { __global const uchar *p0, *p1; float f; } stream_t;

inline stream_t stream_at(__global const uchar *restrict stack, uint pixb, float s)
{
    stream_t st;
    const int si = fast_floor(s);
    st.p0 = stack + (size_t)frame_index(si) * FRAME_BYTES + pixb;
#if INTERP
    st.p1 = stack + (size_t)frame_index(si + 1) * FRAME_BYTES + pixb;
    st.f = s - (float)si;
#else
    st.p1 = st.p0;
    st.f = 0.0f;
#endif
    return st;
}

inline float16 load16(stream_t st, int o)
{
    float16 v = convert_float16(vload16(0, st.p0 + o));
#if INTERP
    v = v + st.f * (convert_float16(vload16(0, st.p1 + o)) - v);
#endif
    return v;
}

inline float load1(stream_t st, int o)
{
    float v = (float)st.p0[o];
#if INTERP
    v = v + st.f * ((float)st.p1[o] - v);
#endif
    return v;
}

// The blend of a byte: its primary source first, the weight of the other one.
inline float blend1(float a, float b, uint code)
{
    const float w = (float)(code & 0x1FFu) * (1.0f / 256.0f);
    const float first = (code & 0x200u) ? b : a;
    const float second = (code & 0x200u) ? a : b;
    return first + w * (second - first);
}

inline float16 blend16(float16 a, float16 b, ushort16 code)
{
    const int16 c = convert_int16(code);
    const float16 w = convert_float16(c & 0x1FF) * (1.0f / 256.0f);
    const int16 swap = (c & 0x200) != 0;           // -1 where the primary source is B
    const float16 first = select(a, b, swap);
    const float16 second = select(b, a, swap);
    return first + w * (second - first);
}

// PoCL's vstore16 of uchar stores byte by byte (4x slower than the whole kernel's other
// work); an under-aligned vector type gives one unaligned 16-byte store.
typedef uchar16 __attribute__((aligned(1))) uchar16_u;

inline void store16(uchar16 v, __global uchar *p)
{
    *(__global uchar16_u *)p = v;
}

// Round to nearest even and saturate to 0..255, as convert_uchar16_sat_rte but ~2x faster on
// PoCL: clamping first makes rounding and saturating commute, and adding 1.5 * 2^23 leaves
// the rounded integer (current rounding mode: nearest even) in the low mantissa bits.
inline uchar16 to_uchar16(float16 v)
{
    return convert_uchar16(as_uint16(clamp(v, 0.0f, 255.0f) + 12582912.0f));
}

// Output bytes [ob, ob + n) of a run whose streams have constant times. With may_spill
// (its last chunk ends within the row: the runs of a row are done in order, left to right,
// by one work-item) the last chunk spills over into the next runs, which rewrite those bytes;
// otherwise it is aligned to the end of the run and overlaps the previous chunk (same
// values), or the run goes byte by byte when shorter than a chunk. The buffers the spill
// may read past (stack, code, gain) are padded by a chunk.
__attribute__((always_inline)) inline void run_const(__global const ushort *restrict code, __global const float *restrict gain,
                      __global uchar *restrict out, size_t ob, int n, bool blend, bool may_spill,
                      stream_t a, stream_t b)
{
    if (may_spill || n >= 16) {
        const int last = may_spill ? n : n - 16;
        if (blend) {
            for (int o0 = 0; o0 < n; o0 += 16) {
                const int o = min(o0, last);
                float16 v = blend16(load16(a, o), load16(b, o), vload16(0, code + ob + o));
#if GAIN
                v *= vload16(0, gain + ob + o);
#endif
                store16(to_uchar16(v), out + ob + o);
            }
        } else {
            for (int o0 = 0; o0 < n; o0 += 16) {
                const int o = min(o0, last);
                float16 v = load16(a, o);
#if GAIN
                v *= vload16(0, gain + ob + o);
#endif
                store16(to_uchar16(v), out + ob + o);
            }
        }
    } else {
        for (int o = 0; o < n; ++o) {
            float v = load1(a, o);
            if (blend)
                v = blend1(v, load1(b, o), code[ob + o]);
#if GAIN
            v *= gain[ob + o];
#endif
            out[ob + o] = convert_uchar_sat_rte(v);
        }
    }
}

__kernel void evolve(__global const uchar *restrict stack,
                     __global const int4 *restrict runs,
                     __global const int2 *restrict runs_b,
                     __global const int *restrict row_start,
                     __global const ushort *restrict code,
                     __global const float *restrict rate,
                     __global const float *restrict run_rate,
                     __global const float *restrict warp,
                     __global const int4 *restrict bframe,
                     __global const float *restrict gain,
                     __global uchar *restrict out,
                     const int height,
                     const float t)
{
    const int y = get_global_id(0);
    if (y >= height)
        return;
    const int r1 = row_start[y + 1];
    for (int r = row_start[y]; r < r1; ++r) {
        const int4 run = runs[r];
        const uint px = (uint)run.x;
        const uint pa = (uint)run.y, la = (uint)run.z;
        const bool blend = ((uint)run.w & BLEND_FLAG) != 0;
        const int npx = (int)((uint)run.w & ~(BLEND_FLAG | SPILL_FLAG));
        uint pb = pa, lb = la;
        if (blend) {
            const int2 rb = runs_b[r];
            pb = (uint)rb.x;
            lb = (uint)rb.y;
        }
        const bool spill = ((uint)run.w & SPILL_FLAG) != 0;
#if RATE
        const float rr = run_rate[r];
        if (rr >= 0.0f) {
            const float tau = fold_time(t * rr);
            run_const(code, gain, out, (size_t)px * 3, npx * 3, blend, spill,
                      stream_at(stack, pa * 3, warp_time(warp, la, tau)),
                      stream_at(stack, pb * 3, warp_time(warp, lb, tau)));
        } else {
            // The rate varies along the run: times per pixel.
            for (int i = 0; i < npx; ++i) {
                const size_t ob = (size_t)(px + i) * 3;
                const float tau = fold_time(t * rate[px + i]);
                const stream_t a = stream_at(stack, (pa + i) * 3, warp_time(warp, la, tau));
                stream_t b = a;
                if (blend)
                    b = stream_at(stack, (pb + i) * 3, warp_time(warp, lb, tau));
                for (int c = 0; c < 3; ++c) {
                    float v = load1(a, c);
                    if (blend)
                        v = blend1(v, load1(b, c), code[ob + c]);
#if GAIN
                    v *= gain[ob + c];
#endif
                    out[ob + c] = convert_uchar_sat_rte(v);
                }
            }
        }
#else
        // Uniform rate: per block, the byte offsets of its two frames and the fraction,
        // computed on the host each frame.
        const int4 fa = bframe[la], fb = bframe[lb];
        stream_t a, b;
        a.p0 = stack + (uint)fa.x + pa * 3; a.p1 = stack + (uint)fa.y + pa * 3; a.f = as_float(fa.z);
        b.p0 = stack + (uint)fb.x + pb * 3; b.p1 = stack + (uint)fb.y + pb * 3; b.f = as_float(fb.z);
        run_const(code, gain, out, (size_t)px * 3, npx * 3, blend, spill, a, b);
#endif
    }
}
