/* Compiled front doors for two hot paths of sherpa_cli.elmo.codec: encode_set and decode_reply.
 *
 * Why C: a pure-Python encode+decode pair spends most of its time in call overhead and in
 * building the Reply tuple, which caps it near 150x the CAN frame rate (benchmark `codec`).
 *
 * Why this is safe: these functions answer only the cases the pure fast paths answer from the
 * codec's own caches (exact str/int/float/bytes, a header the checked path already validated),
 * reading the very same dicts. Anything else -- a cache miss, another type, a value out of
 * range, keywords, any error on the way -- is handed unchanged to the pure-Python function, so
 * bytes, replies and errors are by construction the pure codec's. tests/test_codec_compiled.py
 * checks that equivalence with hypothesis. Without a C compiler the package installs without
 * this module and codec.py keeps its pure functions.
 *
 * State is per module object (multi-phase init), so each interpreter binds its own codec.py.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

/* What codec.py binds, as one tuple: a call holds one reference to it for its whole length,
 * so a bind() run by a finalizer mid-call cannot free what the call is reading. */
enum { INT_SETS, FLOAT_SETS, INT_REPLIES, FLOAT_REPLIES, REPLY_TYPE, PURE_ENCODE_SET, PURE_DECODE_REPLY, N_BOUND };

typedef struct {
    PyObject *bound; /* tuple of N_BOUND, or NULL before codec.py called bind() */
} codec_state;

static codec_state *
state_of(PyObject *module)
{
    return (codec_state *)PyModule_GetState(module);
}

static PyObject *
bind(PyObject *module, PyObject *args)
{
    PyObject *sets_i, *sets_f, *replies_i, *replies_f, *rtype, *pure_enc, *pure_dec, *bound, *old;
    codec_state *st = state_of(module);
    if (st == NULL)
        return NULL;
    if (!PyArg_ParseTuple(args, "O!O!O!O!O!OO:bind", &PyDict_Type, &sets_i, &PyDict_Type, &sets_f,
                          &PyDict_Type, &replies_i, &PyDict_Type, &replies_f, &PyType_Type, &rtype,
                          &pure_enc, &pure_dec))
        return NULL;
    if (!PyType_IsSubtype((PyTypeObject *)rtype, &PyTuple_Type)) {
        PyErr_SetString(PyExc_TypeError, "bind: the reply type must be a tuple subclass");
        return NULL;
    }
    if (!PyCallable_Check(pure_enc) || !PyCallable_Check(pure_dec)) {
        PyErr_SetString(PyExc_TypeError, "bind: the pure encode_set and decode_reply must be callable");
        return NULL;
    }
    bound = PyTuple_Pack(N_BOUND, sets_i, sets_f, replies_i, replies_f, rtype, pure_enc, pure_dec);
    if (bound == NULL)
        return NULL;
    old = st->bound; /* replace first, release after: releasing may run code that calls us */
    st->bound = bound;
    Py_XDECREF(old);
    Py_RETURN_NONE;
}

/* A new reference to the bound tuple. A function unpickled in a fresh process finds its module
 * unbound: importing codec.py binds it. */
static PyObject *
bound_of(PyObject *module)
{
    codec_state *st = state_of(module);
    if (st == NULL)
        return NULL;
    if (st->bound == NULL) {
        PyObject *codec = PyImport_ImportModule("sherpa_cli.elmo.codec");
        if (codec == NULL)
            return NULL;
        Py_DECREF(codec);
        if (st->bound == NULL) {
            PyErr_SetString(PyExc_RuntimeError,
                            "sherpa_cli.elmo._codec_c is not bound to codec.py (is SHERPA_PURE_CODEC set?)");
            return NULL;
        }
    }
    return Py_NewRef(st->bound);
}

/* The 8-byte frame for a cached header and an exact int or float, or NULL when the pure path
 * must answer (not cached, out of int32, not finite, too large for float32, any error). */
static PyObject *
encode_cached(PyObject *bound, PyObject *letters, PyObject *index, PyObject *value)
{
    PyObject *cache, *key, *header;
    int is_float;
    unsigned char out[8];

    if (!PyUnicode_CheckExact(letters) || !PyLong_CheckExact(index)) /* True must not find index 1 */
        return NULL;
    if (PyLong_CheckExact(value))
        is_float = 0, cache = PyTuple_GET_ITEM(bound, INT_SETS);
    else if (PyFloat_CheckExact(value))
        is_float = 1, cache = PyTuple_GET_ITEM(bound, FLOAT_SETS);
    else
        return NULL;
    key = PyTuple_Pack(2, letters, index);
    if (key == NULL)
        goto failed;
    header = PyDict_GetItemWithError(cache, key); /* borrowed: copied out before anything can run */
    Py_DECREF(key);
    if (header == NULL || !PyBytes_CheckExact(header) || PyBytes_GET_SIZE(header) != 4)
        goto failed;
    memcpy(out, PyBytes_AS_STRING(header), 4);
    if (is_float) {
        double x = PyFloat_AS_DOUBLE(value);
        if (!isfinite(x) || PyFloat_Pack4(x, (char *)out + 4, 1) < 0) /* the pure path words it */
            goto failed;
    } else {
        int overflow;
        long long v = PyLong_AsLongLongAndOverflow(value, &overflow);
        uint32_t u;
        if (overflow || v < INT32_MIN || v > INT32_MAX)
            goto failed;
        u = (uint32_t)v; /* two's complement by definition of unsigned conversion */
        out[4] = (unsigned char)(u & 0xFF);
        out[5] = (unsigned char)((u >> 8) & 0xFF);
        out[6] = (unsigned char)((u >> 16) & 0xFF);
        out[7] = (unsigned char)((u >> 24) & 0xFF);
    }
    return PyBytes_FromStringAndSize((const char *)out, 8);
failed:
    /* e.g. a str subclass key whose __eq__ raises: the pure path catches that and checks */
    PyErr_Clear();
    return NULL;
}

static PyObject *
encode_set(PyObject *module, PyObject *const *args, Py_ssize_t nargs, PyObject *kwnames)
{
    PyObject *bound = bound_of(module), *result = NULL;
    if (bound == NULL)
        return NULL;
    if (kwnames == NULL && nargs == 3)
        result = encode_cached(bound, args[0], args[1], args[2]);
    if (result == NULL)
        result = PyObject_Vectorcall(PyTuple_GET_ITEM(bound, PURE_ENCODE_SET), args, nargs, kwnames);
    Py_DECREF(bound);
    return result;
}

static uint32_t
le_u32(const unsigned char *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

/* A Reply for a success frame whose header is cached, or NULL when the pure path must answer
 * (header not cached, float not finite, any error). */
static PyObject *
decode_cached(PyObject *bound, PyObject *data)
{
    const unsigned char *p = (const unsigned char *)PyBytes_AS_STRING(data);
    PyTypeObject *reply_type = (PyTypeObject *)PyTuple_GET_ITEM(bound, REPLY_TYPE);
    PyObject *key, *known, *letters, *index, *value, *reply;
    int is_float = 0;
    uint32_t raw;

    key = PyLong_FromUnsignedLong(le_u32(p));
    if (key == NULL)
        goto failed;
    known = PyDict_GetItemWithError(PyTuple_GET_ITEM(bound, INT_REPLIES), key);
    if (known == NULL && !PyErr_Occurred()) {
        known = PyDict_GetItemWithError(PyTuple_GET_ITEM(bound, FLOAT_REPLIES), key);
        is_float = 1;
    }
    Py_DECREF(key);
    if (known == NULL || !PyTuple_CheckExact(known) || PyTuple_GET_SIZE(known) != 2)
        goto failed;
    /* Own the fields before allocating: a collection run by an allocation may run code that
     * clears the caches. */
    letters = Py_NewRef(PyTuple_GET_ITEM(known, 0));
    index = Py_NewRef(PyTuple_GET_ITEM(known, 1));
    if (is_float) {
        double x = PyFloat_Unpack4((const char *)p + 4, 1);
        value = (x == -1.0 && PyErr_Occurred()) || !isfinite(x) ? NULL : PyFloat_FromDouble(x);
    } else {
        raw = le_u32(p + 4); /* int32 without relying on how a cast wraps */
        value = PyLong_FromLongLong((long long)raw - ((raw & 0x80000000u) ? 0x100000000LL : 0));
    }
    reply = value == NULL ? NULL : reply_type->tp_alloc(reply_type, 5); /* as tuple.__new__ does */
    if (reply == NULL) {
        Py_DECREF(letters);
        Py_DECREF(index);
        Py_XDECREF(value);
        goto failed;
    }
    PyTuple_SET_ITEM(reply, 0, letters);
    PyTuple_SET_ITEM(reply, 1, index);
    PyTuple_SET_ITEM(reply, 2, value);
    PyTuple_SET_ITEM(reply, 3, Py_NewRef(is_float ? Py_True : Py_False));
    PyTuple_SET_ITEM(reply, 4, Py_NewRef(Py_None));
    return reply;
failed:
    PyErr_Clear();
    return NULL;
}

static PyObject *
decode_reply(PyObject *module, PyObject *const *args, Py_ssize_t nargs, PyObject *kwnames)
{
    PyObject *bound = bound_of(module), *result = NULL;
    if (bound == NULL)
        return NULL;
    if (kwnames == NULL && nargs == 1 && PyBytes_CheckExact(args[0]) && PyBytes_GET_SIZE(args[0]) == 8)
        result = decode_cached(bound, args[0]);
    if (result == NULL)
        result = PyObject_Vectorcall(PyTuple_GET_ITEM(bound, PURE_DECODE_REPLY), args, nargs, kwnames);
    Py_DECREF(bound);
    return result;
}

static PyMethodDef methods[] = {
    {"bind", bind, METH_VARARGS,
     "bind(int_sets, float_sets, int_replies, float_replies, Reply, pure_encode_set, pure_decode_reply)\n"
     "--\n\nShare codec.py's caches, reply type and pure functions (called by codec.py on import)."},
    {"encode_set", (PyCFunction)(void (*)(void))encode_set, METH_FASTCALL | METH_KEYWORDS,
     "encode_set(letters, index, value)\n--\n\n"
     "8-byte set frame; the type bit and the value's type come from the command table."},
    {"decode_reply", (PyCFunction)(void (*)(void))decode_reply, METH_FASTCALL | METH_KEYWORDS,
     "decode_reply(data)\n--\n\nDecode an 8-byte TPDO2 reply. Letters need not be in the table."},
    {NULL, NULL, 0, NULL},
};

static int
module_traverse(PyObject *module, visitproc visit, void *arg)
{
    codec_state *st = state_of(module);
    if (st != NULL)
        Py_VISIT(st->bound);
    return 0;
}

static int
module_clear(PyObject *module)
{
    codec_state *st = state_of(module);
    if (st != NULL)
        Py_CLEAR(st->bound);
    return 0;
}

static void
module_free(void *module)
{
    module_clear((PyObject *)module);
}

static PyModuleDef_Slot slots[] = {
#ifdef Py_mod_multiple_interpreters
    {Py_mod_multiple_interpreters, Py_MOD_PER_INTERPRETER_GIL_SUPPORTED},
#endif
    {0, NULL},
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT,
    .m_name = "sherpa_cli.elmo._codec_c",
    .m_doc = "Compiled fast paths of sherpa_cli.elmo.codec (encode_set, decode_reply); see codec.py.",
    .m_size = sizeof(codec_state),
    .m_methods = methods,
    .m_slots = slots,
    .m_traverse = module_traverse,
    .m_clear = module_clear,
    .m_free = module_free,
};

PyMODINIT_FUNC
PyInit__codec_c(void)
{
    return PyModuleDef_Init(&module_def);
}
