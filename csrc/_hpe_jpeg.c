/* One rectangle of a JPEG, decoded with libjpeg-turbo to OpenCV's exact pixels, doing less work than a
 * whole-frame decode: the rows above the rectangle are entropy-decoded only (jpeg_skip_scanlines), the
 * columns outside it are not transformed (jpeg_crop_scanline), and decoding stops at its last row.
 *
 * A band two iMCUs wide is decoded around the rectangle and dropped by the caller, so the fancy chroma
 * upsampling at the rectangle's edges sees the same neighbours as in a whole-frame decode. Settings are
 * OpenCV's (cv2.imdecode): ISLOW integer IDCT, fancy upsampling, libjpeg's own RGB/BGR conversion.
 * hpe_cli/io/jpeg.py compares the first rectangle of every process with OpenCV's decode byte for byte;
 * tests/io/test_jpeg_region.py does so on the real samples and on every chroma subsampling.
 *
 * decode_region(data, top, left, bottom, right, rgb)
 *     -> (bytearray, rows, stride, H, W, y0, x0, dy, dx) or None
 *
 * The rectangle [top, bottom) x [left, right) is clipped to the H x W frame, giving [y0, y0 + h) x [x0, x0 + w);
 * the bytearray holds `rows` rows of `stride` bytes (3 per pixel) and the clipped rectangle starts at row dy,
 * pixel dx of it. None (the caller then decodes the whole frame with OpenCV) when the clipped rectangle is
 * empty, when the data is not an 8-bit Huffman-coded 3-component YCbCr JPEG without an Adobe marker, when the
 * frame has more pixels than OpenCV decodes, when the band does not fit in memory, or when libjpeg reports any
 * error or warning (corrupt or truncated data).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <setjmp.h>
#include <stdio.h>
#include <jpeglib.h>

/* OpenCV's own limit on a decoded image (CV_IO_MAX_IMAGE_PIXELS, 2^30 by default): a larger frame is left
 * to OpenCV, which refuses it, whatever the rectangle asked for */
#define HPE_MAX_PIXELS (1LL << 30)

struct hpe_err {
    struct jpeg_error_mgr pub;
    jmp_buf jump;
};

static void hpe_error_exit(j_common_ptr cinfo) { longjmp(((struct hpe_err *)cinfo->err)->jump, 1); }

static void hpe_emit_message(j_common_ptr cinfo, int level)
{
    if (level < 0) /* a warning: corrupt data; counted, never printed */
        cinfo->err->num_warnings++;
}

static void hpe_output_message(j_common_ptr cinfo) { (void)cinfo; }

static int imin(int a, int b) { return a < b ? a : b; }
static int imax(int a, int b) { return a > b ? a : b; }

static PyObject *decode_region(PyObject *self, PyObject *args)
{
    Py_buffer buf;
    int top, left, bottom, right, rgb;
    struct jpeg_decompress_struct cinfo;
    struct hpe_err jerr;
    PyObject *volatile out = NULL;
    JSAMPROW *volatile ptrs = NULL;
    PyThreadState *volatile save = NULL;
    volatile int created = 0;
    int H, W, y0, x0, h, w, dy0, dx0, dx1, nrows, k, done;
    long warnings;
    JDIMENSION xoff, width;
    Py_ssize_t stride;
    unsigned char *dst;

    (void)self;
    if (!PyArg_ParseTuple(args, "y*iiiip", &buf, &top, &left, &bottom, &right, &rgb))
        return NULL;
    cinfo.err = jpeg_std_error(&jerr.pub);
    jerr.pub.error_exit = hpe_error_exit;
    jerr.pub.emit_message = hpe_emit_message;
    jerr.pub.output_message = hpe_output_message;
    if (setjmp(jerr.jump)) { /* libjpeg's error_exit: undo what is held, the caller decodes with OpenCV */
        if (save)
            PyEval_RestoreThread(save);
        if (created)
            jpeg_destroy_decompress(&cinfo);
        PyMem_Free(ptrs);
        Py_XDECREF(out);
        PyBuffer_Release(&buf);
        Py_RETURN_NONE;
    }
    jpeg_create_decompress(&cinfo);
    created = 1;
    jpeg_mem_src(&cinfo, (const unsigned char *)buf.buf, (unsigned long)buf.len);
    jpeg_read_header(&cinfo, TRUE);
    H = (int)cinfo.image_height;
    W = (int)cinfo.image_width;
    y0 = imax(top, 0);
    x0 = imax(left, 0);
    h = imin(bottom, H) - y0;
    w = imin(right, W) - x0;
    if (h <= 0 || w <= 0 || cinfo.num_components != 3 || cinfo.data_precision != 8 || cinfo.arith_code ||
        cinfo.saw_Adobe_marker || cinfo.jpeg_color_space != JCS_YCbCr || jerr.pub.num_warnings ||
        (long long)H * W > HPE_MAX_PIXELS) {
        jpeg_destroy_decompress(&cinfo);
        PyBuffer_Release(&buf);
        Py_RETURN_NONE;
    }
    cinfo.out_color_space = rgb ? JCS_EXT_RGB : JCS_EXT_BGR;
    cinfo.dct_method = JDCT_ISLOW;
    cinfo.do_fancy_upsampling = TRUE;
    save = PyEval_SaveThread();
    jpeg_start_decompress(&cinfo);
    dy0 = imax(y0 - 2 * cinfo.max_v_samp_factor * DCTSIZE, 0);
    dx0 = imax(x0 - 2 * cinfo.max_h_samp_factor * DCTSIZE, 0);
    dx1 = imin(x0 + w + 2 * cinfo.max_h_samp_factor * DCTSIZE, W);
    xoff = (JDIMENSION)dx0;
    width = (JDIMENSION)(dx1 - dx0);
    if (dx0 > 0 || dx1 < W)
        jpeg_crop_scanline(&cinfo, &xoff, &width); /* widens to iMCU boundaries */
    else
        xoff = 0;
    PyEval_RestoreThread(save);
    save = NULL;
    stride = (Py_ssize_t)cinfo.output_width * 3;
    nrows = y0 + h - dy0;
    out = PyByteArray_FromStringAndSize(NULL, (Py_ssize_t)nrows * stride);
    ptrs = out ? (JSAMPROW *)PyMem_Malloc(sizeof(JSAMPROW) * (size_t)nrows) : NULL;
    if (!ptrs) { /* no memory for the band: declined, like any other frame this module does not decode */
        PyErr_Clear();
        jpeg_destroy_decompress(&cinfo);
        Py_XDECREF(out);
        PyBuffer_Release(&buf);
        Py_RETURN_NONE;
    }
    dst = (unsigned char *)PyByteArray_AS_STRING(out);
    for (k = 0; k < nrows; k++)
        ptrs[k] = dst + (Py_ssize_t)k * stride;
    save = PyEval_SaveThread();
    if (dy0 > 0)
        jpeg_skip_scanlines(&cinfo, (JDIMENSION)dy0);
    while ((int)cinfo.output_scanline < y0 + h) {
        k = (int)cinfo.output_scanline - dy0; /* rows straight into the output, as many as libjpeg gives */
        if (jpeg_read_scanlines(&cinfo, ptrs + k, (JDIMENSION)(nrows - k)) == 0)
            break;
    }
    done = (int)cinfo.output_scanline >= y0 + h;
    jpeg_abort_decompress(&cinfo);
    PyEval_RestoreThread(save);
    save = NULL;
    warnings = jerr.pub.num_warnings;
    jpeg_destroy_decompress(&cinfo);
    PyMem_Free(ptrs);
    PyBuffer_Release(&buf);
    if (warnings || !done) {
        Py_DECREF(out);
        Py_RETURN_NONE;
    }
    return Py_BuildValue("(Nniiiiiii)", out, (Py_ssize_t)nrows, (int)stride, H, W, y0, x0, y0 - dy0,
                         x0 - (int)xoff);
}

static PyMethodDef methods[] = {
    {"decode_region", decode_region, METH_VARARGS,
     "decode_region(data, top, left, bottom, right, rgb) -> (bytearray, rows, stride, H, W, y0, x0, dy, dx) | None"},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_hpe_jpeg", "Rectangles of JPEGs decoded with libjpeg-turbo (hpe_cli.io.jpeg).", -1,
    methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__hpe_jpeg(void) { return PyModule_Create(&module); }
