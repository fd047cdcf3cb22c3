/* The FMI 2.0 co-simulation interface of a cotwin d-model FMU.
 *
 * This file is the same for every module. What differs comes from two generated files: model.h and
 * model.c (the module's cycle, cotwin.dmodel.ccode) and ports.h (its ports as tables and the code that
 * moves port values in and out of the model, cotwin.dmodel.fmu from cotwin.dmodel.ports).
 *
 * An instance keeps every port value in three arrays (reals, integers, Booleans), indexed by the
 * port's slot; fmi2Set* and fmi2Get* only touch these arrays and fmi2DoStep runs the model's cycles
 * between them. Its whole state is plain memory (the model holds no pointers), so an FMU state is a
 * copy of it, tagged with the layout it belongs to: fmi2GetFMUstate, fmi2SetFMUstate and
 * (de)serialisation are memory copies, and a state from another module or build is refused.
 * Serialised bytes may come from anywhere (a file): they carry a header (magic, format version, size,
 * layout tag), and fmi2DeSerializeFMUstate checks every field the code indexes or loops by
 * (model_check, generated with the model) before it hands out a state, so that no bytes can make the
 * FMU read or write outside its memory.
 *
 * Beyond FMI, cotwin_ports tells an in-process master where those arrays are, so that it can move
 * a step's port values without a call per type (cotwin.cosim.units.FMUUnit uses it when present).
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "model.h"
#include "ports.h"

#define SLOTS(n) ((n) > 0 ? (n) : 1)

typedef struct {
    double r[SLOTS(N_REAL)];
    int64_t i[SLOTS(N_INTEGER)];
    bool b[SLOTS(N_BOOLEAN)];
} Values;

/* Everything that evolves: what fmi2GetFMUstate saves and fmi2SetFMUstate restores. */
typedef struct {
    uint64_t tag; /* STATE_TAG of the layout this state was taken from */
    Model model;
    Values values;
    int initialised; /* the model has run model_init */
} State;

/* The serialised form of a State: this header, then the State's bytes. */
#define STATE_MAGIC "cotwinFS"
#define STATE_VERSION 2u
typedef struct {
    char magic[8];    /* STATE_MAGIC */
    uint32_t version; /* STATE_VERSION: the layout of these bytes */
    uint32_t size;    /* sizeof(State) */
    uint64_t tag;     /* STATE_TAG */
} StateHeader;

typedef struct {
    State state;
    fmi2CallbackFunctions functions;
    char *name;
    int logging;
    int merged; /* an output raised in two cycles of one step was reported (once per instance) */
} Instance;

static void log_message(Instance *inst, fmi2Status status, const char *category, const char *message) {
    if (inst->functions.logger)
        inst->functions.logger(inst->functions.componentEnvironment, inst->name ? inst->name : "", status,
                               category, "%s", message);
}

static fmi2Status fail(Instance *inst, const char *function, const char *detail) {
    char text[400];
    snprintf(text, sizeof text, "%s: %s", function, detail);
    log_message(inst, fmi2Error, "logStatusError", text);
    return fmi2Error;
}

static void defaults(State *s) {
    memset(s, 0, sizeof *s);
    s->tag = STATE_TAG;
    ports_start_values(s->values.r, s->values.i, s->values.b);
}

/* Parameters into the model and its initial values; nonzero if these fail (s->model.message says where). */
static int start_model(State *s) {
    ports_parameters(&s->model, s->values.r, s->values.i, s->values.b);
    s->initialised = 1;
    return model_init(&s->model);
}

#define INSTANCE(c, function)                          \
    Instance *inst = (Instance *)(c);                  \
    if (!inst) return fmi2Error;                       \
    static const char *const this_function = function; \
    (void)this_function

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)fmuGUID; (void)fmuResourceLocation; (void)visible;
    if (fmuType != fmi2CoSimulation) return NULL;
    Instance *inst = calloc(1, sizeof(Instance));
    if (!inst) return NULL;
    if (functions) inst->functions = *functions;
    const char *name = instanceName ? instanceName : "";
    inst->name = malloc(strlen(name) + 1);
    if (!inst->name) {
        free(inst);
        return NULL;
    }
    strcpy(inst->name, name);
    inst->logging = loggingOn != fmi2False;
    defaults(&inst->state);
    return inst;
}

void fmi2FreeInstance(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (!inst) return;
    free(inst->name);
    free(inst);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String categories[]) {
    INSTANCE(c, "fmi2SetDebugLogging");
    (void)n; (void)categories;
    inst->logging = on != fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    INSTANCE(c, "fmi2SetupExperiment");
    (void)toleranceDefined; (void)tolerance; (void)startTime; (void)stopTimeDefined; (void)stopTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    INSTANCE(c, "fmi2EnterInitializationMode");
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    INSTANCE(c, "fmi2ExitInitializationMode");
    if (start_model(&inst->state)) return fail(inst, this_function, inst->state.model.message);
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    INSTANCE(c, "fmi2Terminate");
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    INSTANCE(c, "fmi2Reset");
    defaults(&inst->state);
    return fmi2OK;
}

/* ---- port values: one loop per call, the type of every value reference checked ---- */

/* The slot of value reference vr if it is a variable of the given kind; else -1 and why in `problem`. */
static int checked_slot(const char *function, fmi2ValueReference vr, char kind, char *problem, size_t size) {
    if (vr >= N_VARIABLES) {
        snprintf(problem, size, "no variable has value reference %u", (unsigned)vr);
        return -1;
    }
    if (port_kind[vr] != kind) {
        snprintf(problem, size, "variable %s (value reference %u) is not of the type %s accesses", port_name[vr],
                 (unsigned)vr, function);
        return -1;
    }
    return port_slot[vr];
}

#define PORT_LOOP(kind, body)                                                                    \
    for (size_t k = 0; k < n; k++) {                                                              \
        char problem[200];                                                                        \
        int slot = checked_slot(this_function, vr[k], kind, problem, sizeof problem);             \
        if (slot < 0) return fail(inst, this_function, problem);                                  \
        body;                                                                                     \
    }                                                                                             \
    return fmi2OK

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    INSTANCE(c, "fmi2GetReal");
    PORT_LOOP('r', value[k] = inst->state.values.r[slot]);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer value[]) {
    INSTANCE(c, "fmi2GetInteger");
    PORT_LOOP('i', value[k] = (fmi2Integer)inst->state.values.i[slot]);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean value[]) {
    INSTANCE(c, "fmi2GetBoolean");
    PORT_LOOP('b', value[k] = inst->state.values.b[slot] ? fmi2True : fmi2False);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String value[]) {
    INSTANCE(c, "fmi2GetString");
    (void)vr; (void)value;
    return n ? fail(inst, this_function, "the FMU has no String variables") : fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    INSTANCE(c, "fmi2SetReal");
    PORT_LOOP('r', inst->state.values.r[slot] = value[k]);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer value[]) {
    INSTANCE(c, "fmi2SetInteger");
    PORT_LOOP('i', inst->state.values.i[slot] = value[k]);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean value[]) {
    INSTANCE(c, "fmi2SetBoolean");
    PORT_LOOP('b', inst->state.values.b[slot] = value[k] != fmi2False);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String value[]) {
    INSTANCE(c, "fmi2SetString");
    (void)vr; (void)value;
    return n ? fail(inst, this_function, "the FMU has no String variables") : fmi2OK;
}

/* ---- cotwin's extension (not FMI): the port arrays of an instance, for an in-process master ----
 * Writes kind[vr] ('r', 'i', 'b') and slot[vr] tables and the instance's arrays of reals (double),
 * integers (int64_t) and Booleans (one-byte bool); returns the number of variables. Between calls of
 * fmi2DoStep the master may read and write these arrays where fmi2Get and fmi2Set would. */
size_t cotwin_ports(fmi2Component c, const char **kind, const int **slot, double **r, int64_t **i, bool **b) {
    Instance *inst = (Instance *)c;
    if (!inst || !kind || !slot || !r || !i || !b) return 0;
    *kind = port_kind;
    *slot = port_slot;
    *r = inst->state.values.r;
    *i = inst->state.values.i;
    *b = inst->state.values.b;
    return N_VARIABLES;
}

/* ---- stepping ---- */

/* The model computes in int64; an FMI Integer is 32 bits. A value beyond that is an error naming the
 * port, never wrapped when an importer reads it (fmi2GetInteger) or the master reads the slot. */
static int integers_fit(State *s) {
    for (int v = 0; v < N_VARIABLES; v++) {
        if (port_kind[v] != 'i') continue;
        int64_t x = s->values.i[port_slot[v]];
        if (x < INT32_MIN || x > INT32_MAX) {
            snprintf(s->model.message, sizeof s->model.message,
                     "port %s = %lld does not fit an FMI Integer (int32) (cycle %lld)", port_name[v],
                     (long long)x, (long long)s->model.cycle);
            return 0;
        }
    }
    return 1;
}

/* One cycle: inputs in (input events only in the first cycle of a step: an occurrence is taken once), the
 * model's cycle, outputs out; *again names an output an earlier cycle of the step raised already. */
static int run_cycle(State *s, int first, const char **again) {
    ports_to_model(&s->model, s->values.r, s->values.i, s->values.b);
    if (!first) ports_clear_input_events(&s->model);
    if (model_step(&s->model)) return 1;
    const char *repeated = ports_from_model(&s->model, s->values.r, s->values.i, s->values.b);
    if (repeated && !*again) *again = repeated;
    return N_INTEGER > 0 && !integers_fit(s);
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    INSTANCE(c, "fmi2DoStep");
    (void)currentCommunicationPoint; (void)noSetFMUStatePriorToCurrentPoint;
    State *s = &inst->state;
    if (!s->initialised && start_model(s)) return fail(inst, this_function, s->model.message);
    double period = s->values.r[PERIOD_SLOT];
    long cycles = period > 0.0 ? lround(communicationStepSize / period) : 1;
    ports_clear_outputs(s->values.r, s->values.i, s->values.b);
    const char *again = NULL;
    for (long k = 0; k < cycles; k++) {
        if (run_cycle(s, k == 0, &again)) return fail(inst, this_function, s->model.message);
    }
    if (again && !inst->merged) { /* a Boolean port carries one occurrence per step: say which was lost */
        char text[400];
        snprintf(text, sizeof text, "%s occurred in several of the %ld cycles of one step (cycle_period %g s): a "
                 "step carries one occurrence, with the values of the last, so the others are lost; with "
                 "cycle_period equal to the step each is kept (further ones not logged)", again, cycles, period);
        log_message(inst, fmi2Warning, "logStatusWarning", text);
        inst->merged = 1;
    }
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    INSTANCE(c, "fmi2CancelStep");
    return fail(inst, this_function, "steps complete synchronously: nothing to cancel");
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)c; (void)s; (void)value;
    return fmi2Discard;
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    (void)c; (void)s; (void)value;
    return fmi2Discard;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)c; (void)s; (void)value;
    return fmi2Discard;
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    (void)c; (void)s; (void)value;
    return fmi2Discard;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)c; (void)s; (void)value;
    return fmi2Discard;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    INSTANCE(c, "fmi2SetRealInputDerivatives");
    (void)vr; (void)n; (void)order; (void)value;
    return fail(inst, this_function, "the FMU does not interpolate inputs");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real value[]) {
    INSTANCE(c, "fmi2GetRealOutputDerivatives");
    (void)vr; (void)n; (void)order; (void)value;
    return fail(inst, this_function, "the FMU has no output derivatives");
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference unknown[], size_t nUnknown,
                                        const fmi2ValueReference known[], size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    INSTANCE(c, "fmi2GetDirectionalDerivative");
    (void)unknown; (void)nUnknown; (void)known; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    return fail(inst, this_function, "the FMU provides no directional derivatives");
}

/* ---- FMU state: a tagged copy of the instance's State ---- */

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    INSTANCE(c, "fmi2GetFMUstate");
    if (!FMUstate) return fail(inst, this_function, "no place for the state (NULL)");
    State *copy = (State *)*FMUstate; /* FMI: a state given back is overwritten */
    if (!copy) copy = malloc(sizeof(State));
    if (!copy) return fail(inst, this_function, "out of memory");
    memcpy(copy, &inst->state, sizeof(State));
    *FMUstate = copy;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    INSTANCE(c, "fmi2SetFMUstate");
    const State *saved = (const State *)FMUstate;
    if (!saved) return fail(inst, this_function, "no state (NULL)");
    if (saved->tag != STATE_TAG) return fail(inst, this_function, "the state belongs to another FMU");
    memcpy(&inst->state, saved, sizeof(State));
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    INSTANCE(c, "fmi2FreeFMUstate");
    if (FMUstate) {
        free(*FMUstate);
        *FMUstate = NULL;
    }
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    INSTANCE(c, "fmi2SerializedFMUstateSize");
    if (!FMUstate || !size) return fail(inst, this_function, "no state or no place for its size (NULL)");
    *size = sizeof(StateHeader) + sizeof(State);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size) {
    INSTANCE(c, "fmi2SerializeFMUstate");
    if (!FMUstate || !serializedState) return fail(inst, this_function, "no state or no buffer (NULL)");
    if (size < sizeof(StateHeader) + sizeof(State))
        return fail(inst, this_function, "the buffer is smaller than fmi2SerializedFMUstateSize");
    StateHeader header;
    memset(&header, 0, sizeof header);
    memcpy(header.magic, STATE_MAGIC, sizeof header.magic);
    header.version = STATE_VERSION;
    header.size = (uint32_t)sizeof(State);
    header.tag = STATE_TAG;
    memcpy(serializedState, &header, sizeof header);
    memcpy(serializedState + sizeof header, FMUstate, sizeof(State));
    return fmi2OK;
}

/* 1 if `s` (bytes of unknown origin) is a state this FMU can run; else 0 and why. */
static int state_check(const State *s, char *why, size_t size) {
    if (s->tag != STATE_TAG) return snprintf(why, size, "a state of another FMU (layout tag)"), 0;
    if (s->initialised != 0 && s->initialised != 1) return snprintf(why, size, "a malformed initialisation flag"), 0;
    for (int k = 0; k < N_BOOLEAN; k++) {
        unsigned char byte;
        memcpy(&byte, &s->values.b[k], 1);
        if (byte > 1) return snprintf(why, size, "Boolean port slot %d is neither true nor false", k), 0;
    }
    double period = s->values.r[PERIOD_SLOT];
    if (!(period >= 0.0) || isinf(period)) return snprintf(why, size, "the cycle period is not a finite number >= 0"), 0;
    return model_check(&s->model, why, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate) {
    INSTANCE(c, "fmi2DeSerializeFMUstate");
    if (!serializedState || !FMUstate) return fail(inst, this_function, "no bytes or no place for the state (NULL)");
    StateHeader header;
    if (size != sizeof header + sizeof(State))
        return fail(inst, this_function, "the bytes are not a state of this FMU (wrong size)");
    memcpy(&header, serializedState, sizeof header);
    if (memcmp(header.magic, STATE_MAGIC, sizeof header.magic) != 0)
        return fail(inst, this_function, "the bytes are not a state of this FMU (no cotwin FMU state header)");
    if (header.version != STATE_VERSION || header.size != sizeof(State))
        return fail(inst, this_function, "the bytes are a state of another version of the FMU's state format");
    if (header.tag != STATE_TAG) return fail(inst, this_function, "the bytes are a state of another FMU");
    State *checked = malloc(sizeof(State));
    if (!checked) return fail(inst, this_function, "out of memory");
    memcpy(checked, serializedState + sizeof header, sizeof(State));
    char why[200];
    if (!state_check(checked, why, sizeof why)) {
        free(checked);
        char text[300];
        snprintf(text, sizeof text, "the bytes are not a state this FMU can run: %s", why);
        return fail(inst, this_function, text);
    }
    if (*FMUstate) { /* FMI: a state given back is overwritten */
        memcpy(*FMUstate, checked, sizeof(State));
        free(checked);
    } else {
        *FMUstate = checked;
    }
    return fmi2OK;
}
