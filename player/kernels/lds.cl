// LDS projection: frame = basis^T (w * x) + mean, written as saturated uint8.
//
// The basis is stored blocked for streaming: for block b of BLOCK consecutive values,
// its n x BLOCK sub-matrix is contiguous (row i at offset (b * n + i) * BLOCK), so one
// work-item reads one contiguous run and consecutive work-items read consecutive runs.
//
// Defines: BLOCK (16), HALF (1: basis stored as half floats), CHANNELS (1 or 3: values per
// pixel of the basis; grey is replicated), PIXEL_BYTES (3 or 4: bytes per output pixel),
// R_AT, G_AT, B_AT (the byte of each colour in an output pixel), A_AT (alpha's, 255; -1: none),
// GROUP (blocks per work-item: 3 for colour in a 4-byte format, whose 48 values are 16 whole
// pixels, placed by shuffles and written as four 16-byte vectors; else 1. The host pads the
// basis and the mean to whole groups).

#if BLOCK != 16
#error "BLOCK must be 16"
#endif

#if HALF
typedef half basis_t;
#define LOAD_AT(r, i) vload_half16(0, (r) + (size_t)(i) * BLOCK)
#else
typedef float basis_t;
#define LOAD_AT(r, i) vload16(0, (r) + (size_t)(i) * BLOCK)
#endif
#define LOAD_ROW(i) LOAD_AT(row, i)

#if GROUP == 3
// Output bytes 16 K .. 16 K + 15 (pixels 4 K .. 4 K + 3) of a group as a shuffle2 of two of its
// three RGB vectors (K 0: p0, p0; 1: p0, p1; 2: p1, p2; 3: p2, p2, whose bytes start at value
// 0, 0, 16, 32): each pixel's colours at R_AT, G_AT, B_AT; alpha lanes are set afterwards.
#define CSEL(s) ((s) == R_AT ? 0 : (s) == G_AT ? 1 : (s) == B_AT ? 2 : 0)
#define PX(K, j, b) (uchar)(3 * (4 * (K) + (j) / 4) + CSEL((j) % 4) - (b))
#define PX4(K, j, b) PX(K, j, b), PX(K, j + 1, b), PX(K, j + 2, b), PX(K, j + 3, b)
#define MASK(K, b) (uchar16)(PX4(K, 0, b), PX4(K, 4, b), PX4(K, 8, b), PX4(K, 12, b))
#define AL(j) (uchar)((j) == A_AT ? 255 : 0)
#define ALPHA (uchar16)(AL(0), AL(1), AL(2), AL(3), AL(0), AL(1), AL(2), AL(3), AL(0), AL(1), AL(2), AL(3), AL(0), AL(1), AL(2), AL(3))
#endif

__kernel void project(__global const basis_t *restrict basis,
                      __global const float *restrict mean,
                      __constant float *restrict coef,
                      __global uchar *restrict out,
                      const int n,
                      const int values)
{
#if GROUP == 3
    const size_t g = get_global_id(0);
    if (g * 3 * BLOCK >= (size_t)values)
        return;  // the global size is rounded up to whole work-groups
    __global const basis_t *r0 = basis + 3 * g * (size_t)n * BLOCK;
    __global const basis_t *r1 = r0 + (size_t)n * BLOCK, *r2 = r1 + (size_t)n * BLOCK;
    float16 a0 = vload16(3 * g, mean), a1 = vload16(3 * g + 1, mean), a2 = vload16(3 * g + 2, mean);
    for (int i = 0; i < n; ++i) {
        const float c = coef[i];
        a0 += c * LOAD_AT(r0, i);
        a1 += c * LOAD_AT(r1, i);
        a2 += c * LOAD_AT(r2, i);
    }
    const uchar16 p0 = convert_uchar16_sat_rte(a0), p1 = convert_uchar16_sat_rte(a1), p2 = convert_uchar16_sat_rte(a2);
    const uchar16 q[4] = {shuffle2(p0, p0, MASK(0, 0)) | ALPHA, shuffle2(p0, p1, MASK(1, 0)) | ALPHA,
                          shuffle2(p1, p2, MASK(2, 16)) | ALPHA, shuffle2(p2, p2, MASK(3, 32)) | ALPHA};
    const size_t first = g * 16;                        // the group's first pixel
    const size_t pixels = (size_t)values / 3;
    for (int k = 0; k < 4; ++k) {
        if (first + 4 * k + 4 <= pixels) {
            vstore16(q[k], 0, out + (first + 4 * k) * 4);
        } else {
            uchar tmp[16];
            vstore16(q[k], 0, tmp);
            for (int j = 0; j < 16 && first * 4 + 16 * k + j < pixels * 4; ++j)
                out[first * 4 + 16 * k + j] = tmp[j];
        }
    }
#else
    const size_t b = get_global_id(0);
    if (b * BLOCK >= (size_t)values)
        return;  // the global size is rounded up to whole work-groups
    __global const basis_t *row = basis + b * (size_t)n * BLOCK;
    float16 acc = vload16(b, mean);
    int i = 0;
    for (; i + 4 <= n; i += 4) {
        acc += coef[i] * LOAD_ROW(i);
        acc += coef[i + 1] * LOAD_ROW(i + 1);
        acc += coef[i + 2] * LOAD_ROW(i + 2);
        acc += coef[i + 3] * LOAD_ROW(i + 3);
    }
    for (; i < n; ++i)
        acc += coef[i] * LOAD_ROW(i);
    uchar16 px = convert_uchar16_sat_rte(acc);
    const size_t first = b * BLOCK;
#if CHANNELS == 3 && PIXEL_BYTES == 3 && R_AT == 0 && G_AT == 1 && B_AT == 2
    if (first + BLOCK <= (size_t)values) {
        vstore16(px, b, out);
        return;
    }
#endif
    uchar tmp[16];
    vstore16(px, 0, tmp);
    for (size_t j = 0; j < BLOCK && first + j < (size_t)values; ++j) {
#if CHANNELS == 3
        const size_t p = (first + j) / 3;
        const int c = (int)(first + j - 3 * p);
        __global uchar *o = out + p * PIXEL_BYTES;
        o[c == 0 ? R_AT : (c == 1 ? G_AT : B_AT)] = tmp[j];
#if A_AT >= 0
        if (c == 0)
            o[A_AT] = 255;
#endif
#else
        __global uchar *o = out + (first + j) * PIXEL_BYTES;
        o[R_AT] = tmp[j];
        o[G_AT] = tmp[j];
        o[B_AT] = tmp[j];
#if A_AT >= 0
        o[A_AT] = 255;
#endif
#endif
    }
#endif
}
