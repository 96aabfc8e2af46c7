// Crossfade / fractional-speed blend of up to four stored frames, in exact integer arithmetic:
//     out = (sum_k w_k * frames[idx_k] + 128) >> 8,   sum_k w_k = 256, 0 <= w_k <= 256.
// The largest sum, 256 * 255 + 128, fits a ushort, so the accumulator is ushort16.
//
// frames holds T frames of FRAME_VECS uchar16 each (every frame padded to 16 bytes);
// one work-item writes one uchar16. params (8 ints, uploaded per frame) holds
// idx_0..idx_3 then w_0..w_3; terms with w_k = 0 are skipped.
//
// Defines: FRAME_VECS (uchar16 per frame).

__kernel void blend(__global const uchar *restrict frames,
                    __constant int *restrict params,
                    __global uchar *restrict out)
{
    const size_t g = get_global_id(0);
    ushort16 acc = (ushort16)(128);
    for (int k = 0; k < 4; ++k) {
        const int w = params[4 + k];
        if (w != 0) {
            const size_t v = (size_t)params[k] * FRAME_VECS + g;
            acc += convert_ushort16(vload16(v, frames)) * (ushort)w;
        }
    }
    vstore16(convert_uchar16(acc >> (ushort)8), g, out);
}
