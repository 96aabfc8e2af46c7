// Crossfade / fractional-speed blend of stored frames, in exact integer arithmetic:
//     out = (sum_k w_k * frame_k + 128) >> 8,   sum_k w_k = 256, 0 <= w_k <= 256.
// The largest sum, 256 * 255 + 128, fits a ushort, so the accumulators are ushort16.
//
// frames holds T RGB frames of FRAME_VECS uchar16 each (every frame padded to 16 * ITEMS
// bytes); params (8 ints, uploaded per frame) holds the frame indices idx_0..idx_3 then the
// weights w_0..w_3. blend2 uses the first two terms (a fractional speed, or a crossfade at
// speed 1); blend4 all four (both at once; unused terms have weight 0). Specialising on the
// term count keeps the inner loop free of branches and parameter loads, which made a generic
// loop 3-5x slower on PoCL.
//
// RGB output (PIXEL_BYTES 3): one work-item writes ITEMS consecutive uchar16 (a one-term frame
// is a plain copy, no kernel). Four-byte output (RGBA, BGRA): the stack stays RGB (3/4 of the
// bytes to read) and one work-item writes 16 whole pixels, 48 RGB bytes blended as above, then
// spread to 64 bytes as uint lanes (colours at R_AT, G_AT, B_AT, alpha 255 at A_AT) and stored
// as one vector. Either way the work-item across the frame's end goes byte (pixel) by byte, so
// the frame can be written straight into the caller's array. blend1 is the one-term frame (a copy that spreads the pixels; its frame index is an
// argument, so a frame is one command).
//
// Defines: FRAME_VECS (uchar16 per frame, a multiple of ITEMS), ITEMS (uchar16 per work-item of
// the RGB kernels), PIXELS (per frame), PIXEL_BYTES, R_AT, G_AT, B_AT, A_AT.

#define FRAME(i) (frames + (size_t)params[i] * FRAME_VECS * 16)


#if PIXEL_BYTES == 3

// Frames are 16-byte aligned in the stack: whole vectors load as such.
#define TERM(p, w) (convert_ushort16(((__global const uchar16 *)(p))[g]) * (w))
#define FRAME_BYTES (PIXELS * 3)

// Work-items wholly inside the frame store whole vectors; the one across its end goes byte by byte.
#define RGB_KERNEL(sum, byte)                                                   \
    const size_t g0 = get_global_id(0) * ITEMS;                                 \
    if ((g0 + ITEMS) * 16 <= FRAME_BYTES) {                                     \
        for (int k = 0; k < ITEMS; ++k) {                                       \
            const size_t g = g0 + k;                                            \
            *(__global uchar16_u *)(out + g * 16) = convert_uchar16(((ushort16)(128) + sum) >> (ushort)8); \
        }                                                                       \
    } else {                                                                    \
        for (size_t e = g0 * 16; e < FRAME_BYTES; ++e)                          \
            out[e] = (uchar)((128 + byte) >> 8);                                \
    }

__kernel void blend2(__global const uchar *restrict frames,
                     __constant int *restrict params,
                     __global uchar *restrict out)
{
    __global const uchar *a = FRAME(0), *b = FRAME(1);
    const ushort wa = (ushort)params[4], wb = (ushort)params[5];
    RGB_KERNEL(TERM(a, wa) + TERM(b, wb), wa * a[e] + wb * b[e])
}

__kernel void blend4(__global const uchar *restrict frames,
                     __constant int *restrict params,
                     __global uchar *restrict out)
{
    __global const uchar *a = FRAME(0), *b = FRAME(1), *c = FRAME(2), *d = FRAME(3);
    const ushort wa = (ushort)params[4], wb = (ushort)params[5], wc = (ushort)params[6], wd = (ushort)params[7];
    RGB_KERNEL(TERM(a, wa) + TERM(b, wb) + TERM(c, wc) + TERM(d, wd), wa * a[e] + wb * b[e] + wc * c[e] + wd * d[e])
}

#else


// Whole groups of 16 pixels: the 48-byte group g of every term is 16-byte aligned.
#define LOAD(p, j) (((__global const uchar16 *)(p))[3 * q + (j)])
#define ACC(sum) convert_uchar16(((ushort16)(128) + sum) >> (ushort)8)
#define T(p, w, j) (convert_ushort16(LOAD(p, j)) * (w))

// The partial last group, pixel by pixel (each byte's weighted sum as in the vector path).
#define TAIL(expr)                                                              \
    for (int i = 16 * q; i < PIXELS; ++i) {                                     \
        uchar rgb[3]; /* not c: a frame's name in blend4 */                     \
        for (int ch = 0; ch < 3; ++ch) {                                        \
            const size_t e = (size_t)i * 3 + ch;                                \
            rgb[ch] = (uchar)(expr);                                            \
        }                                                                       \
        put1(rgb[0], rgb[1], rgb[2], out + (size_t)i * 4);                      \
    }

__kernel void blend1(__global const uchar *restrict frames,
                     const int first,
                     __global uchar *restrict out)
{
    __global const uchar *a = frames + (size_t)first * FRAME_VECS * 16;
    const int q = get_global_id(0);
    if (16 * q + 16 <= PIXELS)
        put16(LOAD(a, 0), LOAD(a, 1), LOAD(a, 2), out + (size_t)q * 64);
    else
        TAIL(a[e])
}

__kernel void blend2(__global const uchar *restrict frames,
                     __constant int *restrict params,
                     __global uchar *restrict out)
{
    __global const uchar *a = FRAME(0), *b = FRAME(1);
    const ushort wa = (ushort)params[4], wb = (ushort)params[5];
    const int q = get_global_id(0);
    if (16 * q + 16 <= PIXELS) {
#define SUM2(j) ACC(T(a, wa, j) + T(b, wb, j))
        put16(SUM2(0), SUM2(1), SUM2(2), out + (size_t)q * 64);
    } else {
        TAIL((128 + wa * a[e] + wb * b[e]) >> 8)
    }
}

__kernel void blend4(__global const uchar *restrict frames,
                     __constant int *restrict params,
                     __global uchar *restrict out)
{
    __global const uchar *a = FRAME(0), *b = FRAME(1), *c = FRAME(2), *d = FRAME(3);
    const ushort wa = (ushort)params[4], wb = (ushort)params[5], wc = (ushort)params[6], wd = (ushort)params[7];
    const int q = get_global_id(0);
    if (16 * q + 16 <= PIXELS) {
#define SUM4(j) ACC(T(a, wa, j) + T(b, wb, j) + T(c, wc, j) + T(d, wd, j))
        put16(SUM4(0), SUM4(1), SUM4(2), out + (size_t)q * 64);
    } else {
        TAIL((128 + wa * a[e] + wb * b[e] + wc * c[e] + wd * d[e]) >> 8)
    }
}

#endif
