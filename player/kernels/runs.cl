// Mode evolve (time-varying textures): frame t gathered from the stored source frames
// through the quilt, at a per-pixel source time: local time tau = t * rate(y, x) (the rate
// map M), folded by the end mode, then passed through the monotone time warp of the
// pixel's block (the jitter f_b, a piecewise-linear table with one knot per source frame).
// Pixels in the cross-fade band of a quilt cut blend a second source (with its own block's
// warp).
//
// Runs instead of a per-pixel gather. The player cuts every output row, once at open,
// into runs: segments whose pixels read at most two *streams*, a stream being one block's
// source pixels at a constant offset (source pixel = x + offset, so a stream is a
// contiguous run of a source frame row). A plain run reads one stream (A); a blend run (a
// cross-fade band, on both sides of its cut) reads two (A and B) and, per output byte, a
// code: the weight of the second source in 1/256 (bits 0-8) and whether the pixel's
// primary source is B (bit 9). One work-item does the runs of one row, left to right.
//
// The rate is constant along every run: the player quantizes the rate map to steps of
// 1/512 and, when a rate map is set, cuts the runs further where the quantized rate
// changes. So are the stream times: the host computes, once per frame, for every *time
// slot* (a pair of rate and block that some run reads) the byte offsets of the two source
// frames and the fraction (bframe; run_pair[r] names the slots of streams A and B, with a
// uniform rate the slot of a block is the block itself), and the run is copied or blended
// as a byte stream (colour channels are just bytes: every operation is per byte) with 16-byte
// vector loads and stores. The last chunk of a run spills up to 15 bytes into the next
// runs of its row, which rewrite them (the host flags the runs whose spill stays within
// the row), or else is aligned to the run's end (rewriting a few bytes with the same
// values); a run shorter than a chunk that may not spill goes byte by byte.
//
// Arithmetic is that of the numpy reference, in float32: v = v0 + f (v1 - v0) per source,
// v = first + a (second - first) for a blend, v *= gain, rounded to nearest even and
// saturated.
//
// The stack, codes and gains hold RGB pixels (3 bytes) whatever the output. A four-byte output
// (RGBA, BGRA) row is drawn exactly so, as RGB bytes into the first 3/4 of its own output row
// (still in cache), then spread in place to its pixels by 16-pixel chunks, 48 bytes to 64 as
// uint lanes (colours at R_AT, G_AT, B_AT, alpha 255 at A_AT), stored as one vector. Chunks of
// whole pixels per run would do: the runs average about 13 pixels, and rounding each up to a
// chunk cost more than the spread.
//
// Defines: INTERP, GAIN (per stack byte), WIDTH (output pixels per row), PIXEL_BYTES, R_AT,
// G_AT, B_AT, A_AT (the output pixel). The end mode, the rate map and the jitter live in the host's per-frame slot table,
// so no control needs another kernel.
//
// Run tables: runs[r] = (first output pixel, pixel of stream A at it, block of A, length |
// blend << 31 | spill << 30), runs_b[r] = (pixel of stream B at the first output pixel,
// block of B), run_pair[r] = (time slot of A, of B); row_start[y] .. row_start[y + 1] are
// the runs of output row y.

#define BLEND_FLAG 0x80000000u
#define SPILL_FLAG 0x40000000u

typedef struct { __global const uchar *p0, *p1; float f; } stream_t;

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

// uchar16_u (pixels.cl): one unaligned 16-byte store where PoCL's vstore16 of uchar stores byte by byte.

inline void store16(uchar16 v, __global uchar *p)
{
    *(__global uchar16_u *)p = v;
}

// Round to nearest even and saturate to 0..255, as convert_uchar16_sat_rte but faster on
// PoCL (CHANGELOG.md): clamping first makes rounding and saturating commute, and adding 1.5 * 2^23 leaves
// the rounded integer (current rounding mode: nearest even) in the low mantissa bits.
inline uchar16 to_uchar16(float16 v)
{
    return convert_uchar16(as_uint16(clamp(v, 0.0f, 255.0f) + 12582912.0f));
}

inline uchar to_uchar(float v)
{
    return (uchar)as_uint(clamp(v, 0.0f, 255.0f) + 12582912.0f);
}

// Output bytes [ob, ob + n) of a run whose streams have constant times. With may_spill
// (its last chunk ends within the row: the runs of a row are done in order, left to right,
// by one work-item) the last chunk spills over into the next runs, which rewrite those bytes;
// otherwise it is aligned to the end of the run and overlaps the previous chunk (same
// values), or the run goes byte by byte when shorter than a chunk. The buffers a spill
// reads past (stack, code, gain) are padded by a chunk.
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
            out[ob + o] = to_uchar(v);
        }
    }
}

#if PIXEL_BYTES == 4


// Spread row y's RGB bytes, drawn at the start of its four-byte output row, to its pixels, in
// place: right to left, a chunk's 48 bytes are read before its 64 are stored, and every store
// lies at or right of what it read (4k >= 3k), so nothing is overwritten before it is read.
inline void spread_row(__global uchar *restrict row)
{
    int k = WIDTH;
    for (; k >= 16; k -= 16)
        put16(vload16(0, row + 3 * (k - 16)), vload16(0, row + 3 * (k - 16) + 16), vload16(0, row + 3 * (k - 16) + 32),
              row + 4 * (k - 16));
    while (k > 0) {
        --k;
        put1(row[3 * k], row[3 * k + 1], row[3 * k + 2], row + 4 * k);  // reads all three before it writes
    }
}

#endif

__kernel void evolve(__global const uchar *restrict stack,
                     __global const int4 *restrict runs,
                     __global const int2 *restrict runs_b,
                     __global const int *restrict row_start,
                     __global const ushort *restrict code,
                     __global const int2 *restrict run_pair,
                     __global const int4 *restrict bframe,
                     __global const float *restrict gain,
                     __global uchar *restrict out,
                     const int height)
{
    const int y = get_global_id(0);
    if (y >= height)
        return;
    const int r1 = row_start[y + 1];
    for (int r = row_start[y]; r < r1; ++r) {
        const int4 run = runs[r];
        const uint px = (uint)run.x;
        const uint pa = (uint)run.y;
        const bool blend = ((uint)run.w & BLEND_FLAG) != 0;
        const int npx = (int)((uint)run.w & ~(BLEND_FLAG | SPILL_FLAG));
        const bool spill = ((uint)run.w & SPILL_FLAG) != 0;
        const int2 slot = run_pair[r];
        const uint pb = blend ? (uint)runs_b[r].x : pa;
        // the stream times of the run's slots: byte offsets of the two frames and the fraction
        const int4 fa = bframe[slot.x], fb = bframe[slot.y];
        stream_t a, b;
        a.p0 = stack + (uint)fa.x + pa * 3; a.p1 = stack + (uint)fa.y + pa * 3; a.f = as_float(fa.z);
        b.p0 = stack + (uint)fb.x + pb * 3; b.p1 = stack + (uint)fb.y + pb * 3; b.f = as_float(fb.z);
#if PIXEL_BYTES == 3
        run_const(code, gain, out, (size_t)px * 3, npx * 3, blend, spill, a, b);
#else
        // RGB bytes at the start of the row's four-byte output: out + 4 W y + 3 x
        run_const(code, gain, out + (size_t)y * WIDTH, (size_t)px * 3, npx * 3, blend, spill, a, b);
#endif
    }
#if PIXEL_BYTES == 4
    spread_row(out + (size_t)y * WIDTH * 4);
#endif
}
