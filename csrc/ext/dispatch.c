/*
 * pyrt.native._dispatch: the ready queue's check-and-dispatch in C.
 *
 * The one file of csrc/ that speaks the CPython API (the kernels beside it
 * are plain C through cffi): a ready-queue check that calls Python routines
 * has to hold references, call them and append their durations, which cffi
 * cannot do without a callback per routine.  It does exactly what
 * pyrt.scheduler.readyqueue.ReadyQueue._check_py does, in the same order:
 *
 *   1. the 8031 check over the byte image (pyrt_rq_check / _wide, readyq.c);
 *   2. with timing on: a new tick log (when tracking), pending += ready,
 *      t0 = timer();
 *   3. per ready address, in slot order: run its body; if it reschedules
 *      itself from a period variable (a byte of a bytearray, or item 0 of a
 *      list), put it in the lowest free slot with that period (a full queue
 *      calls the queue's own _put, which raises QueueFullError); with timing
 *      on, t1 = timer(), append t1 - t0 to the routine's sample list (and
 *      (address, t1 - t0) to the tick log), t0 = t1: one clock read per
 *      dispatch, the end of one routine being the start of the next.
 *
 * An exception from a body (or an address with no routine: KeyError) stops
 * the walk and propagates; ``last`` names the address that was running.
 * ``running`` is the address whose body runs now (0 between bodies and
 * after a walk): who writes an output is read from it (a store per
 * dispatch).  After an exception it still names the routine that raised,
 * until the queue has handled the fault and clears it.
 * The timer is CLOCK_MONOTONIC read directly when the queue's timer is
 * time.perf_counter_ns (what that function reads on Linux), otherwise the
 * Python callable, so a test's fake timer gives the same figures.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <structmember.h>
#include <stdint.h>
#include <time.h>

#include "../readyq.h"

#define NADDR 65536

typedef struct {
    PyObject *fn;       /* the body */
    PyObject *pmem;     /* NULL, a bytearray or a list: where the period is */
    Py_ssize_t paddr;
    PyObject *samples;  /* list of durations, or NULL */
} entry;

typedef struct {
    PyObject_HEAD
    Py_buffer view;     /* the byte image (held: it cannot be resized) */
    int have_view;
    pyrt_rq rq;
    uint16_t ready[256];
    int wide;
    uint16_t *index;    /* address -> entry number + 1 (0: none) */
    entry *entries;
    Py_ssize_t n_entries, cap_entries;
    PyObject *timer;    /* NULL: timing off */
    int monotonic;      /* read CLOCK_MONOTONIC instead of calling timer */
    int track;
    PyObject *full;     /* full(address, n): raises QueueFullError */
    PyObject *tick_log; /* list of (address, duration) of the last check */
    long long checked_at;
    long long pending;
    long last;
    long running;       /* the address whose body runs now (0: none) */
} Dispatcher;

static void clear_entry(entry *e)
{
    Py_CLEAR(e->fn);
    Py_CLEAR(e->pmem);
    Py_CLEAR(e->samples);
}

static int Dispatcher_traverse(Dispatcher *self, visitproc visit, void *arg)
{
    Py_ssize_t i;
    for (i = 0; i < self->n_entries; i++) {
        Py_VISIT(self->entries[i].fn);
        Py_VISIT(self->entries[i].pmem);
        Py_VISIT(self->entries[i].samples);
    }
    Py_VISIT(self->timer);
    Py_VISIT(self->full);
    Py_VISIT(self->tick_log);
    return 0;
}

static int Dispatcher_clear(Dispatcher *self)
{
    Py_ssize_t i;
    for (i = 0; i < self->n_entries; i++)
        clear_entry(&self->entries[i]);
    Py_CLEAR(self->timer);
    Py_CLEAR(self->full);
    Py_CLEAR(self->tick_log);
    return 0;
}

static void Dispatcher_dealloc(Dispatcher *self)
{
    PyObject_GC_UnTrack(self);
    Dispatcher_clear(self);
    if (self->have_view)
        PyBuffer_Release(&self->view);
    PyMem_Free(self->entries);
    PyMem_Free(self->index);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static int Dispatcher_init(Dispatcher *self, PyObject *args, PyObject *kwds)
{
    static char *kwlist[] = {"mem", "t_addr", "q_addr", "capacity", "wide", NULL};
    PyObject *mem;
    int t_addr, q_addr, capacity, wide = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "Oiii|p", kwlist, &mem, &t_addr, &q_addr,
                                     &capacity, &wide))
        return -1;
    if (self->have_view) {
        PyErr_SetString(PyExc_TypeError, "a Dispatcher is bound once");
        return -1;
    }
    if (!PyByteArray_Check(mem)) {
        PyErr_Format(PyExc_TypeError, "the byte image must be a bytearray, got %s",
                     Py_TYPE(mem)->tp_name);
        return -1;
    }
    if (capacity < 1 || capacity > 255) {
        PyErr_Format(PyExc_ValueError, "ready queue capacity must be 1..255, got %d", capacity);
        return -1;
    }
    if (PyObject_GetBuffer(mem, &self->view, PyBUF_WRITABLE) < 0)
        return -1;
    self->have_view = 1;
    if (t_addr < 0 || q_addr < 0 || t_addr + (wide ? 4 : 1) * capacity > self->view.len ||
        q_addr + 2 * capacity > self->view.len) {
        PyErr_SetString(PyExc_ValueError, "T or Q lies outside the byte image");
        return -1;
    }
    self->index = PyMem_Calloc(NADDR, sizeof(uint16_t));
    if (self->index == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    self->rq.mem = (uint8_t *)self->view.buf;
    self->rq.mem_len = (int32_t)self->view.len;
    self->rq.t_addr = t_addr;
    self->rq.q_addr = q_addr;
    self->rq.capacity = capacity;
    self->rq.ready = self->ready;
    self->wide = wide;
    self->checked_at = -1;
    self->last = 0;
    self->running = 0;
    return 0;
}

/* set_routine(address, fn, pmem, paddr): what runs at address. */
static PyObject *Dispatcher_set_routine(Dispatcher *self, PyObject *args)
{
    long address;
    Py_ssize_t paddr;
    PyObject *fn, *pmem;
    entry *e;
    if (!PyArg_ParseTuple(args, "lOOn", &address, &fn, &pmem, &paddr))
        return NULL;
    if (self->index == NULL) {
        PyErr_SetString(PyExc_TypeError, "Dispatcher not bound");
        return NULL;
    }
    if (address < 1 || address > 0xFFFF) {
        PyErr_Format(PyExc_ValueError, "routine address must be 0001..FFFF, got %ld", address);
        return NULL;
    }
    if (!PyCallable_Check(fn)) {
        PyErr_SetString(PyExc_TypeError, "a routine body must be callable");
        return NULL;
    }
    if (pmem == Py_None) {
        pmem = NULL;
    } else if (!PyByteArray_Check(pmem) && !PyList_Check(pmem)) {
        PyErr_SetString(PyExc_TypeError, "a period variable is a bytearray or a list");
        return NULL;
    } else if (paddr < 0) {
        PyErr_SetString(PyExc_ValueError, "negative period address");
        return NULL;
    }
    if (self->index[address]) {
        e = &self->entries[self->index[address] - 1];
    } else {
        if (self->n_entries >= NADDR - 1) {
            PyErr_SetString(PyExc_ValueError, "too many routines");
            return NULL;
        }
        if (self->n_entries == self->cap_entries) {
            Py_ssize_t cap = self->cap_entries ? 2 * self->cap_entries : 8;
            entry *grown = PyMem_Realloc(self->entries, cap * sizeof(entry));
            if (grown == NULL)
                return PyErr_NoMemory();
            self->entries = grown;
            self->cap_entries = cap;
        }
        e = &self->entries[self->n_entries];
        e->fn = e->pmem = e->samples = NULL;
        self->n_entries++;
        self->index[address] = (uint16_t)self->n_entries;
    }
    Py_INCREF(fn);
    Py_XSETREF(e->fn, fn);
    Py_XINCREF(pmem);
    Py_XSETREF(e->pmem, pmem);
    e->paddr = paddr;
    Py_RETURN_NONE;
}

/* set_timing(timer, monotonic, track, samples): timer None turns timing off;
   samples maps address -> list (routines not in it record nothing). */
static PyObject *Dispatcher_set_timing(Dispatcher *self, PyObject *args)
{
    PyObject *timer, *samples;
    int monotonic, track;
    if (!PyArg_ParseTuple(args, "OppO", &timer, &monotonic, &track, &samples))
        return NULL;
    if (timer != Py_None && !PyCallable_Check(timer)) {
        PyErr_SetString(PyExc_TypeError, "timer must be callable or None");
        return NULL;
    }
    if (samples != Py_None && !PyDict_Check(samples)) {
        PyErr_SetString(PyExc_TypeError, "samples must be a dict or None");
        return NULL;
    }
    if (timer == Py_None) {
        Py_CLEAR(self->timer);
    } else {
        Py_INCREF(timer);
        Py_XSETREF(self->timer, timer);
    }
    self->monotonic = monotonic;
    self->track = track;
    return PyObject_CallMethod((PyObject *)self, "set_samples", "O", samples);
}

/* set_samples(samples): the sample list of each routine (a dict address ->
   list, or None). */
static PyObject *Dispatcher_set_samples(Dispatcher *self, PyObject *samples)
{
    Py_ssize_t i;
    if (samples != Py_None && !PyDict_Check(samples)) {
        PyErr_SetString(PyExc_TypeError, "samples must be a dict or None");
        return NULL;
    }
    for (i = 0; i < self->n_entries; i++)
        Py_CLEAR(self->entries[i].samples);
    if (samples != Py_None) {
        PyObject *key, *value;
        Py_ssize_t pos = 0;
        while (PyDict_Next(samples, &pos, &key, &value)) {
            long a = PyLong_AsLong(key);
            if (a == -1 && PyErr_Occurred())
                return NULL;
            if (a < 1 || a > 0xFFFF || !self->index[a])
                continue;
            if (!PyList_Check(value)) {
                PyErr_SetString(PyExc_TypeError, "a sample list must be a list");
                return NULL;
            }
            Py_INCREF(value);
            Py_XSETREF(self->entries[self->index[a] - 1].samples, value);
        }
    }
    Py_RETURN_NONE;
}

static PyObject *Dispatcher_set_full(Dispatcher *self, PyObject *full)
{
    if (!PyCallable_Check(full)) {
        PyErr_SetString(PyExc_TypeError, "full must be callable");
        return NULL;
    }
    Py_INCREF(full);
    Py_XSETREF(self->full, full);
    Py_RETURN_NONE;
}

static inline int read_timer(Dispatcher *self, long long *out)
{
    if (self->monotonic) {
        struct timespec ts;
        clock_gettime(CLOCK_MONOTONIC, &ts);
        *out = (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
        return 0;
    } else {
        PyObject *r = PyObject_CallNoArgs(self->timer);
        if (r == NULL)
            return -1;
        *out = PyLong_AsLongLong(r);
        Py_DECREF(r);
        return (*out == -1 && PyErr_Occurred()) ? -1 : 0;
    }
}

/* Put address in the lowest free slot with schedule value n (checked by
   the caller); 1 on success, 0 when the queue is full. */
static inline int put(Dispatcher *self, uint16_t address, unsigned long n)
{
    uint8_t *mem = self->rq.mem;
    uint8_t *q = mem + self->rq.q_addr;
    int32_t i, cap = self->rq.capacity;
    for (i = 0; i < cap; i++, q += 2) {
        if (q[0] | q[1])
            continue;
        if (self->wide) {
            uint8_t *t = mem + self->rq.t_addr + 4 * i;
            t[0] = (uint8_t)n;
            t[1] = (uint8_t)(n >> 8);
            t[2] = (uint8_t)(n >> 16);
            t[3] = (uint8_t)(n >> 24);
        } else {
            mem[self->rq.t_addr + i] = (uint8_t)n;
        }
        q[0] = (uint8_t)address;
        q[1] = (uint8_t)(address >> 8);
        return 1;
    }
    return 0;
}

/* Read the period variable of e; -1 with an exception set on a bad value. */
static long long read_period(Dispatcher *self, entry *e)
{
    unsigned long long n;
    if (PyByteArray_Check(e->pmem)) {
        if (e->paddr >= PyByteArray_GET_SIZE(e->pmem)) {
            PyErr_SetString(PyExc_IndexError, "bytearray index out of range");
            return -1;
        }
        n = (uint8_t)PyByteArray_AS_STRING(e->pmem)[e->paddr];
    } else {
        PyObject *v;
        if (e->paddr >= PyList_GET_SIZE(e->pmem)) {
            PyErr_SetString(PyExc_IndexError, "list index out of range");
            return -1;
        }
        v = PyList_GET_ITEM(e->pmem, e->paddr);
        n = PyLong_AsUnsignedLongLong(v);
        if (n == (unsigned long long)-1 && PyErr_Occurred())
            return -1;
    }
    if (n > (self->wide ? 0xFFFFFFFFULL : 0xFFULL)) {
        PyErr_Format(PyExc_ValueError, "schedule value %llu does not fit T", n);
        return -1;
    }
    return (long long)n;
}

/* check(now_ns): one queue check and the dispatch of what it found ready.
   Returns the samples pending (timing on) or 0. */
static PyObject *Dispatcher_check(Dispatcher *self, PyObject *arg)
{
    int32_t k, n_ready;
    long long t0 = 0, t1, now;
    PyObject *log = NULL;
    int timing = self->timer != NULL;
    if (self->index == NULL) {
        PyErr_SetString(PyExc_TypeError, "Dispatcher not bound");
        return NULL;
    }
    if ((self->wide ? pyrt_rq_check_wide(&self->rq) : pyrt_rq_check(&self->rq)) != 0) {
        PyErr_SetString(PyExc_ValueError, "ready queue check: bad queue layout");
        return NULL;
    }
    n_ready = self->rq.n_ready;
    if (n_ready == 0)
        return PyLong_FromLongLong(self->pending);
    if (timing) {
        if (self->track) {
            now = PyLong_AsLongLong(arg);
            if (now == -1 && PyErr_Occurred())
                return NULL;
            log = PyList_New(0);
            if (log == NULL)
                return NULL;
            Py_XSETREF(self->tick_log, log);
            self->checked_at = now;
        }
        self->pending += n_ready;
        if (read_timer(self, &t0) < 0)
            return NULL;
    }
    for (k = 0; k < n_ready; k++) {
        uint16_t a = self->ready[k];
        uint16_t idx = self->index[a];
        entry *e;
        PyObject *r;
        self->last = a;
        if (!idx) {
            PyObject *key = PyLong_FromLong(a);
            if (key != NULL) {
                PyErr_SetObject(PyExc_KeyError, key);
                Py_DECREF(key);
            }
            return NULL;
        }
        e = &self->entries[idx - 1];
        self->running = a;
        r = PyObject_CallNoArgs(e->fn);
        if (r == NULL)
            return NULL;  /* running still names it: the fault's reflex is its */
        Py_DECREF(r);
        /* the body may have re-bound this routine: look it up again */
        e = &self->entries[self->index[a] - 1];
        if (e->pmem != NULL) {
            long long n = read_period(self, e);
            if (n < 0)
                return NULL;
            if (!put(self, a, (unsigned long)n)) {
                r = PyObject_CallFunction(self->full, "iL", (int)a, n);
                if (r == NULL)
                    return NULL;
                Py_DECREF(r);
            }
        }
        if (timing) {
            PyObject *d;
            if (read_timer(self, &t1) < 0)
                return NULL;
            d = PyLong_FromLongLong(t1 - t0);
            if (d == NULL)
                return NULL;
            if (e->samples == NULL) {
                Py_DECREF(d);
                PyObject *key = PyLong_FromLong(a);
                if (key != NULL) {
                    PyErr_SetObject(PyExc_KeyError, key);
                    Py_DECREF(key);
                }
                return NULL;
            }
            if (PyList_Append(e->samples, d) < 0) {
                Py_DECREF(d);
                return NULL;
            }
            if (log != NULL) {
                PyObject *pair = Py_BuildValue("(iO)", (int)a, d);
                if (pair == NULL || PyList_Append(log, pair) < 0) {
                    Py_XDECREF(pair);
                    Py_DECREF(d);
                    return NULL;
                }
                Py_DECREF(pair);
            }
            Py_DECREF(d);
            t0 = t1;
        }
        self->running = 0;
    }
    return PyLong_FromLongLong(self->pending);
}

static PyObject *Dispatcher_get_tick_log(Dispatcher *self, void *closure)
{
    (void)closure;
    if (self->tick_log == NULL)
        return PyList_New(0);
    Py_INCREF(self->tick_log);
    return self->tick_log;
}

static PyMethodDef Dispatcher_methods[] = {
    {"check", (PyCFunction)Dispatcher_check, METH_O,
     "check(now_ns): check the queue and run the routines found ready."},
    {"set_routine", (PyCFunction)Dispatcher_set_routine, METH_VARARGS,
     "set_routine(address, fn, pmem, paddr): the body at address and its period variable."},
    {"set_timing", (PyCFunction)Dispatcher_set_timing, METH_VARARGS,
     "set_timing(timer, monotonic, track, samples): timing on (timer) or off (None)."},
    {"set_samples", (PyCFunction)Dispatcher_set_samples, METH_O,
     "set_samples(samples): each routine's sample list (dict address -> list)."},
    {"set_full", (PyCFunction)Dispatcher_set_full, METH_O,
     "set_full(full): full(address, n) is called when no slot is free (it raises)."},
    {NULL, NULL, 0, NULL},
};

static PyMemberDef Dispatcher_members[] = {
    {"pending", T_LONGLONG, offsetof(Dispatcher, pending), 0,
     "samples recorded since the last take"},
    {"checked_at", T_LONGLONG, offsetof(Dispatcher, checked_at), 0,
     "loop time of the last check that ran a routine with tracking on (-1: none)"},
    {"last", T_LONG, offsetof(Dispatcher, last), READONLY,
     "address of the routine dispatched last (the one that raised, after an error)"},
    {"running", T_LONG, offsetof(Dispatcher, running), 0,
     "address of the routine whose body runs now, 0 between bodies; after an error "
     "the one that raised, until the queue clears it (its fault handled)"},
    {NULL, 0, 0, 0, NULL},
};

static PyGetSetDef Dispatcher_getset[] = {
    {"tick_log", (getter)Dispatcher_get_tick_log, NULL,
     "(address, duration) of the routines run in the last tracked check", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyTypeObject DispatcherType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "pyrt.native._dispatch.Dispatcher",
    .tp_doc = "A ready queue's check-and-dispatch over its byte image.",
    .tp_basicsize = sizeof(Dispatcher),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Dispatcher_init,
    .tp_dealloc = (destructor)Dispatcher_dealloc,
    .tp_traverse = (traverseproc)Dispatcher_traverse,
    .tp_clear = (inquiry)Dispatcher_clear,
    .tp_methods = Dispatcher_methods,
    .tp_members = Dispatcher_members,
    .tp_getset = Dispatcher_getset,
};

static struct PyModuleDef dispatch_module = {
    PyModuleDef_HEAD_INIT, "_dispatch",
    "The ready queue's check-and-dispatch in C (csrc/ext/dispatch.c).", -1, NULL,
    NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__dispatch(void)
{
    PyObject *m;
    if (PyType_Ready(&DispatcherType) < 0)
        return NULL;
    m = PyModule_Create(&dispatch_module);
    if (m == NULL)
        return NULL;
    Py_INCREF(&DispatcherType);
    if (PyModule_AddObject(m, "Dispatcher", (PyObject *)&DispatcherType) < 0) {
        Py_DECREF(&DispatcherType);
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
