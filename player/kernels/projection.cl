// LDS projection: frame = basis^T (w * x) + mean, written as saturated uint8.
//
// The basis is stored blocked for streaming: for block b of BLOCK consecutive values,
// its n x BLOCK sub-matrix is contiguous (row i at offset (b * n + i) * BLOCK), so one
// work-item reads one contiguous run and consecutive work-items read consecutive runs.
//
// Defines: BLOCK (16), HALF (1: basis stored as half floats), CHANNELS (1 or 3: values per
// pixel of the basis; grey is replicated), PIXEL_BYTES (3 or 4: bytes per output pixel),
// R_AT, G_AT, B_AT (the byte of each colour in an output pixel), A_AT (alpha's, 255; -1: none).

#if BLOCK != 16
#error "BLOCK must be 16"
#endif

#if HALF
typedef half basis_t;
#define LOAD_ROW(i) vload_half16(0, row + (size_t)(i) * BLOCK)
#else
typedef float basis_t;
#define LOAD_ROW(i) vload16(0, row + (size_t)(i) * BLOCK)
#endif

__kernel void project(__global const basis_t *restrict basis,
                      __global const float *restrict mean,
                      __constant float *restrict coef,
                      __global uchar *restrict out,
                      const int n,
                      const int values)
{
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
}
