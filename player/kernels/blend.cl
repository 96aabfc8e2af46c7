// Crossfade / fractional-speed blend of stored frames, in exact integer arithmetic:
//     out = (sum_k w_k * frame_k + 128) >> 8,   sum_k w_k = 256, 0 <= w_k <= 256.
// The largest sum, 256 * 255 + 128, fits a ushort, so the accumulators are ushort16.
//
// frames holds T frames of FRAME_VECS uchar16 each (every frame padded to 16 * ITEMS
// bytes); one work-item writes ITEMS consecutive uchar16. params (8 ints, uploaded per
// frame) holds the frame indices idx_0..idx_3 then the weights w_0..w_3. blend2 uses the
// first two terms (a fractional speed, or a crossfade at speed 1); blend4 all four (both at
// once; unused terms have weight 0). Specialising on the term count keeps the inner loop
// free of branches and parameter loads, which made a generic loop 3-5x slower on PoCL.
//
// Defines: FRAME_VECS (uchar16 per frame, a multiple of ITEMS), ITEMS (uchar16 per work-item).

#define FRAME(i) (frames + (size_t)params[i] * FRAME_VECS * 16)
#define TERM(p, w) (convert_ushort16(vload16(g, p)) * (w))

__kernel void blend2(__global const uchar *restrict frames,
                     __constant int *restrict params,
                     __global uchar *restrict out)
{
    __global const uchar *a = FRAME(0), *b = FRAME(1);
    const ushort wa = (ushort)params[4], wb = (ushort)params[5];
    const size_t g0 = get_global_id(0) * ITEMS;
    for (int k = 0; k < ITEMS; ++k) {
        const size_t g = g0 + k;
        ushort16 acc = (ushort16)(128) + TERM(a, wa) + TERM(b, wb);
        vstore16(convert_uchar16(acc >> (ushort)8), g, out);
    }
}

__kernel void blend4(__global const uchar *restrict frames,
                     __constant int *restrict params,
                     __global uchar *restrict out)
{
    __global const uchar *a = FRAME(0), *b = FRAME(1), *c = FRAME(2), *d = FRAME(3);
    const ushort wa = (ushort)params[4], wb = (ushort)params[5], wc = (ushort)params[6], wd = (ushort)params[7];
    const size_t g0 = get_global_id(0) * ITEMS;
    for (int k = 0; k < ITEMS; ++k) {
        const size_t g = g0 + k;
        ushort16 acc = (ushort16)(128) + TERM(a, wa) + TERM(b, wb) + TERM(c, wc) + TERM(d, wd);
        vstore16(convert_uchar16(acc >> (ushort)8), g, out);
    }
}
