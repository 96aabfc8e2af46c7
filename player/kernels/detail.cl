// Fine detail and colour range: out = clamp(round(src + gain * (w0 * vol[layer 0] + w1 * vol[layer 1])), low, high),
// or clamp(src, low, high) where that colour's bin ((r >> 3) * 1024 + (g >> 3) * 32 + (b >> 3))
// is not in the source's colour set (colours[bin] == 0).
//
// src is a projected frame in the output pixel format; the volume (Tv, Hv, Wv, CHANNELS) int8
// wraps in y and x; each layer reads volume frame t_k at offset (oy_k, ox_k). One work-item per
// pixel. Contraction is off so that the result equals the numpy reference bit for bit.
//
// Defines: CHANNELS (1 or 3: values per pixel of the model; grey is replicated), VH and VW (the
// volume's rows and columns: constants, so that the wrap is a multiply and shift, or a mask for
// powers of two, rather than a division), PIXEL_BYTES, R_AT, G_AT, B_AT, A_AT (as in projection.cl).

#pragma OPENCL FP_CONTRACT OFF

__kernel void add_detail(__global const uchar *restrict src,
                         __global const char *restrict vol,
                         __global const float *restrict gain,
                         __global const uchar *restrict low,
                         __global const uchar *restrict high,
                         __global const uchar *restrict colours,
                         __global uchar *restrict out,
                         const int width,
                         const int height,
                         const int t0,
                         const int oy0,
                         const int ox0,
                         const float w0,
                         const int t1,
                         const int oy1,
                         const int ox1,
                         const float w1)
{
    const int x = get_global_id(0);
    const int y = get_global_id(1);
    if (x >= width || y >= height)
        return;
    const size_t p = (size_t)y * width + x;
    const size_t i0 = (((size_t)t0 * VH + (y + oy0) % VH) * VW + (x + ox0) % VW) * CHANNELS;
    const size_t i1 = (((size_t)t1 * VH + (y + oy1) % VH) * VW + (x + ox1) % VW) * CHANNELS;
    const float g = gain[p];
    __global const uchar *s = src + p * PIXEL_BYTES;
    __global uchar *o = out + p * PIXEL_BYTES;
    uchar v[CHANNELS];
    for (int c = 0; c < CHANNELS; ++c) {
        const float n = w0 * (float)vol[i0 + c] + w1 * (float)vol[i1 + c];
        const int at = c == 0 ? R_AT : (c == 1 ? G_AT : B_AT);
        const uchar u = convert_uchar_sat_rte((float)s[at] + g * n);
        v[c] = clamp(u, low[p * CHANNELS + c], high[p * CHANNELS + c]);
    }
#if CHANNELS == 3
    const int bin = ((v[0] >> 3) << 10) | ((v[1] >> 3) << 5) | (v[2] >> 3);
#else
    const int bin = ((v[0] >> 3) << 10) | ((v[0] >> 3) << 5) | (v[0] >> 3);
#endif
    if (!colours[bin]) {
        for (int c = 0; c < CHANNELS; ++c) {
            const int at = c == 0 ? R_AT : (c == 1 ? G_AT : B_AT);
            v[c] = clamp(s[at], low[p * CHANNELS + c], high[p * CHANNELS + c]);
        }
    }
#if CHANNELS == 3
    o[R_AT] = v[0];
    o[G_AT] = v[1];
    o[B_AT] = v[2];
#else
    o[R_AT] = v[0];
    o[G_AT] = v[0];
    o[B_AT] = v[0];
#endif
#if A_AT >= 0
    o[A_AT] = 255;
#endif
}
