/* Compiled front doors for two hot paths of sherpa_cli.elmo.codec: encode_set and decode_reply.
 *
 * Why C: a pure-Python encode+decode pair spends most of its time in call overhead and in
 * building the Reply tuple, which caps it near 150x the CAN frame rate (benchmark `codec`).
 *
 * Why this is safe: these functions answer only the cases the pure fast paths answer from the
 * codec's own caches (exact str/int/float/bytes, a header the checked path already validated),
 * reading the very same dicts. Anything else -- a cache miss, another type, a value out of
 * range, keywords -- is handed unchanged to the pure-Python function, so bytes, replies and
 * errors are by construction the pure codec's. tests/test_codec_compiled.py checks that
 * equivalence with hypothesis. Without a C compiler the package installs without this module
 * and codec.py keeps its pure functions.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

/* Set once by bind(); strong references, kept for the life of the process. */
static PyObject *int_sets, *float_sets;       /* (letters, index) -> 4-byte header of a set */
static PyObject *int_replies, *float_replies; /* u32 reply header -> (letters, index) */
static PyTypeObject *reply_type;               /* codec.Reply, a tuple subclass */
static PyObject *pure_encode_set, *pure_decode_reply;

static PyObject *
bind(PyObject *module, PyObject *args)
{
    PyObject *sets_i, *sets_f, *replies_i, *replies_f, *pure_enc, *pure_dec;
    PyTypeObject *rtype;
    if (!PyArg_ParseTuple(args, "O!O!O!O!O!OO:bind", &PyDict_Type, &sets_i, &PyDict_Type, &sets_f,
                          &PyDict_Type, &replies_i, &PyDict_Type, &replies_f, &PyType_Type, &rtype,
                          &pure_enc, &pure_dec))
        return NULL;
    if (!PyType_IsSubtype(rtype, &PyTuple_Type)) {
        PyErr_SetString(PyExc_TypeError, "bind: the reply type must be a tuple subclass");
        return NULL;
    }
    if (!PyCallable_Check(pure_enc) || !PyCallable_Check(pure_dec)) {
        PyErr_SetString(PyExc_TypeError, "bind: the pure encode_set and decode_reply must be callable");
        return NULL;
    }
    Py_XSETREF(int_sets, Py_NewRef(sets_i));
    Py_XSETREF(float_sets, Py_NewRef(sets_f));
    Py_XSETREF(int_replies, Py_NewRef(replies_i));
    Py_XSETREF(float_replies, Py_NewRef(replies_f));
    Py_XSETREF(reply_type, (PyTypeObject *)Py_NewRef((PyObject *)rtype));
    Py_XSETREF(pure_encode_set, Py_NewRef(pure_enc));
    Py_XSETREF(pure_decode_reply, Py_NewRef(pure_dec));
    Py_RETURN_NONE;
}

static int
not_bound(void)
{
    if (pure_encode_set == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "sherpa_cli.elmo._codec_c is used before codec.py bound it");
        return 1;
    }
    return 0;
}

/* The 8-byte frame for a cached header and an exact int or float, or NULL with no error set
 * when the pure path must answer (not cached, out of int32, not finite, too large for float32). */
static PyObject *
encode_cached(PyObject *letters, PyObject *index, PyObject *value)
{
    PyObject *cache, *key, *header;
    int is_float;
    char out[8];

    if (!PyUnicode_CheckExact(letters) || !PyLong_CheckExact(index)) /* True must not find index 1 */
        return NULL;
    if (PyLong_CheckExact(value))
        is_float = 0, cache = int_sets;
    else if (PyFloat_CheckExact(value))
        is_float = 1, cache = float_sets;
    else
        return NULL;
    key = PyTuple_Pack(2, letters, index);
    if (key == NULL)
        return NULL;
    header = PyDict_GetItemWithError(cache, key); /* borrowed; str and int keys hash without code */
    Py_DECREF(key);
    if (header == NULL || !PyBytes_CheckExact(header) || PyBytes_GET_SIZE(header) != 4)
        return NULL;
    memcpy(out, PyBytes_AS_STRING(header), 4);
    if (is_float) {
        double x = PyFloat_AS_DOUBLE(value);
        if (!isfinite(x))
            return NULL;
        if (PyFloat_Pack4(x, out + 4, 1) < 0) { /* OverflowError: the pure path words it */
            PyErr_Clear();
            return NULL;
        }
    } else {
        int overflow;
        long long v = PyLong_AsLongLongAndOverflow(value, &overflow);
        uint32_t u;
        if (overflow || v < INT32_MIN || v > INT32_MAX)
            return NULL;
        u = (uint32_t)(int32_t)v;
        out[4] = (char)(u & 0xFF);
        out[5] = (char)((u >> 8) & 0xFF);
        out[6] = (char)((u >> 16) & 0xFF);
        out[7] = (char)((u >> 24) & 0xFF);
    }
    return PyBytes_FromStringAndSize(out, 8);
}

static PyObject *
encode_set(PyObject *module, PyObject *const *args, Py_ssize_t nargs, PyObject *kwnames)
{
    if (not_bound())
        return NULL;
    if (kwnames == NULL && nargs == 3) {
        PyObject *frame = encode_cached(args[0], args[1], args[2]);
        if (frame != NULL || PyErr_Occurred())
            return frame;
    }
    return PyObject_Vectorcall(pure_encode_set, args, nargs, kwnames);
}

static uint32_t
le_u32(const unsigned char *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

/* A Reply for a success frame whose header is cached, or NULL with no error set when the pure
 * path must answer (header not cached, float not finite). */
static PyObject *
decode_cached(PyObject *data)
{
    const unsigned char *p = (const unsigned char *)PyBytes_AS_STRING(data);
    PyObject *key, *known, *letters, *index, *value, *reply;
    int is_float = 0;

    key = PyLong_FromUnsignedLong(le_u32(p));
    if (key == NULL)
        return NULL;
    known = PyDict_GetItemWithError(int_replies, key);
    if (known == NULL && !PyErr_Occurred()) {
        known = PyDict_GetItemWithError(float_replies, key);
        is_float = 1;
    }
    Py_DECREF(key);
    if (known == NULL || !PyTuple_CheckExact(known) || PyTuple_GET_SIZE(known) != 2)
        return NULL;
    if (is_float) {
        double x = PyFloat_Unpack4((const char *)p + 4, 1);
        if (x == -1.0 && PyErr_Occurred())
            return NULL;
        if (!isfinite(x))
            return NULL;
        value = PyFloat_FromDouble(x);
    } else {
        value = PyLong_FromLong((long)(int32_t)le_u32(p + 4));
    }
    if (value == NULL)
        return NULL;
    /* Own the fields before allocating: a collection run by the allocation may run code that
     * clears the caches. */
    letters = Py_NewRef(PyTuple_GET_ITEM(known, 0));
    index = Py_NewRef(PyTuple_GET_ITEM(known, 1));
    reply = reply_type->tp_alloc(reply_type, 5); /* how tuple.__new__ makes a subclass instance */
    if (reply == NULL) {
        Py_DECREF(letters);
        Py_DECREF(index);
        Py_DECREF(value);
        return NULL;
    }
    PyTuple_SET_ITEM(reply, 0, letters);
    PyTuple_SET_ITEM(reply, 1, index);
    PyTuple_SET_ITEM(reply, 2, value);
    PyTuple_SET_ITEM(reply, 3, Py_NewRef(is_float ? Py_True : Py_False));
    PyTuple_SET_ITEM(reply, 4, Py_NewRef(Py_None));
    return reply;
}

static PyObject *
decode_reply(PyObject *module, PyObject *data)
{
    if (not_bound())
        return NULL;
    if (PyBytes_CheckExact(data) && PyBytes_GET_SIZE(data) == 8) {
        PyObject *reply = decode_cached(data);
        if (reply != NULL || PyErr_Occurred())
            return reply;
    }
    return PyObject_CallOneArg(pure_decode_reply, data);
}

static PyMethodDef methods[] = {
    {"bind", bind, METH_VARARGS,
     "bind(int_sets, float_sets, int_replies, float_replies, Reply, pure_encode_set, pure_decode_reply)\n"
     "--\n\nShare codec.py's caches, reply type and pure functions (called once, by codec.py)."},
    {"encode_set", (PyCFunction)(void (*)(void))encode_set, METH_FASTCALL | METH_KEYWORDS,
     "encode_set(letters, index, value)\n--\n\n"
     "8-byte set frame; the type bit and the value's type come from the command table."},
    {"decode_reply", decode_reply, METH_O,
     "decode_reply(data)\n--\n\nDecode an 8-byte TPDO2 reply. Letters need not be in the table."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT,
    .m_name = "sherpa_cli.elmo._codec_c",
    .m_doc = "Compiled fast paths of sherpa_cli.elmo.codec (encode_set, decode_reply); see codec.py.",
    .m_size = -1,
    .m_methods = methods,
};

PyMODINIT_FUNC
PyInit__codec_c(void)
{
    return PyModule_Create(&module_def);
}
