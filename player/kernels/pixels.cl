// RGB pixels placed in the output's pixel format: used where a kernel writes RGB only (the x86
// gather variant) and the player was asked for RGBA or BGRA. Numerical contract: exact bytes,
// as PixelFormat.from_rgb (player/pixels.py).
//
// Defines: PIXEL_BYTES (4), R_AT, G_AT, B_AT (the byte of each colour), A_AT (alpha's, 255).
// One work-item places 16 pixels (48 bytes read, 64 written; the host rounds the global
// size up and the tail is done pixel by pixel).

__kernel void place(__global const uchar *restrict rgb, __global uchar *restrict out, const int n)
{
    const int first = get_global_id(0) * 16;
    if (first >= n)
        return;
    if (first + 16 <= n) {
        uchar tmp[48];
        vstore16(vload16(0, rgb + (size_t)first * 3), 0, tmp);
        vstore16(vload16(0, rgb + (size_t)first * 3 + 16), 0, tmp + 16);
        vstore16(vload16(0, rgb + (size_t)first * 3 + 32), 0, tmp + 32);
        uchar px[64];
        for (int i = 0; i < 16; ++i) {
            px[i * PIXEL_BYTES + R_AT] = tmp[3 * i];
            px[i * PIXEL_BYTES + G_AT] = tmp[3 * i + 1];
            px[i * PIXEL_BYTES + B_AT] = tmp[3 * i + 2];
            px[i * PIXEL_BYTES + A_AT] = 255;
        }
        for (int k = 0; k < 4; ++k)
            vstore16(vload16(k, px), 0, out + (size_t)first * PIXEL_BYTES + 16 * k);
        return;
    }
    for (int i = first; i < n; ++i) {
        __global uchar *o = out + (size_t)i * PIXEL_BYTES;
        o[R_AT] = rgb[3 * (size_t)i];
        o[G_AT] = rgb[3 * (size_t)i + 1];
        o[B_AT] = rgb[3 * (size_t)i + 2];
        o[A_AT] = 255;
    }
}
