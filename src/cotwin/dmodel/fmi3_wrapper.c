/* The FMI 3.0 co-simulation interface of a cotwin d-model FMU, with the d-model's cycle as a clock.
 *
 * The same for every module, like fmi2_wrapper.c, from the same generated model.h/model.c and ports.h,
 * plus fmi3ports.h (cotwin.dmodel.fmi3): which value references are clocked, the clock's value
 * reference and the default cycle period.
 *
 * The clock `cycle` is a time-based, fixed periodic input clock: its interval is the parameter
 * cycle_period (> 0), its shift 0, so it ticks at start + k * cycle_period. One tick is one d-model
 * cycle. Every port but cycle_period is clocked by it: input events and their values are read at a
 * tick, operation calls, output events and `state` are written at one.
 *
 * With Event Mode (instantiated with eventModeUsed): the importer enters Event Mode at a tick, activates
 * the clock (fmi3SetClock), sets the inputs, calls fmi3UpdateDiscreteStates (the cycle runs; an input
 * event is consumed by it) and reads the outputs before fmi3EnterStepMode; fmi3DoStep then runs no
 * cycle, signals eventHandlingNeeded when it ends on the next tick, and refuses to pass a tick that
 * was not activated (or returns early at it, when the importer allows early return).
 * Without Event Mode the FMU handles the clock itself, as the standard asks: fmi3DoStep runs a cycle
 * per tick in [t, t + h), the inputs in the first, outputs true if they occurred in any of them (the
 * FMI 2.0 FMU's behaviour when the step is a multiple of the period).
 * Outputs may be read at any time (the values of the last tick); a clocked input is set at a tick (in
 * Event Mode), in Initialization Mode, or in Step Mode when Event Mode is not used.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "model.h"
#include "ports.h"
#include "fmi3ports.h"

#define SLOTS(n) ((n) > 0 ? (n) : 1)

enum Mode { INSTANTIATED, INITIALIZATION, EVENT, STEP, TERMINATED, FAILED };
static const char *const mode_name[] = {"Instantiated", "Initialization Mode", "Event Mode", "Step Mode",
                                        "Terminated", "an error state"};

typedef struct {
    double r[SLOTS(N_REAL)];
    int64_t i[SLOTS(N_INTEGER)];
    bool b[SLOTS(N_BOOLEAN)];
} Values;

/* Everything that evolves: what fmi3GetFMUState saves and fmi3SetFMUState restores. */
typedef struct {
    uint64_t tag;   /* STATE_TAG ^ FMI3_TAG: states of this FMU only */
    Model model;
    Values values;
    int initialised;
    int mode;
    double start;   /* the start time: ticks at start + k * period */
    double time;    /* the FMU's current time */
    int64_t ticks;  /* the next tick is tick number `ticks` */
    int clock;      /* the clock is active (Event Mode, between fmi3SetClock and fmi3UpdateDiscreteStates) */
} State;

typedef struct {
    State state;
    fmi3InstanceEnvironment environment;
    fmi3LogMessageCallback log;
    char *name;
    int logging;
    int event_mode_used;
    int early_return_allowed;
} Instance;

static void log_message(Instance *inst, fmi3Status status, const char *category, const char *message) {
    if (inst->log) inst->log(inst->environment, status, category, message);
}

static fmi3Status fail(Instance *inst, const char *function, const char *detail) {
    char text[480];
    snprintf(text, sizeof text, "%s: %s", function, detail);
    log_message(inst, fmi3Error, "logStatusError", text);
    return fmi3Error;
}

static void defaults(State *s) {
    memset(s, 0, sizeof *s);
    s->tag = STATE_TAG ^ FMI3_TAG;
    ports_start_values(s->values.r, s->values.i, s->values.b);
    s->values.r[PERIOD_SLOT] = DEFAULT_PERIOD;
}

#define INSTANCE(c, function)                          \
    Instance *inst = (Instance *)(c);                  \
    if (!inst) return fmi3Error;                       \
    static const char *const this_function = function; \
    (void)this_function

#define IN_MODE(condition, what)                                                                 \
    do {                                                                                         \
        if (!(condition)) {                                                                      \
            char problem[200];                                                                   \
            snprintf(problem, sizeof problem, "not allowed in %s (%s)", mode_name[inst->state.mode], what); \
            return fail(inst, this_function, problem);                                           \
        }                                                                                        \
    } while (0)

static double period(const State *s) { return s->values.r[PERIOD_SLOT]; }
static double tick_time(const State *s, int64_t k) { return s->start + (double)k * period(s); }
static double tolerance(const State *s) { return 1e-9 * (fabs(s->time) + period(s)); }

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean on, size_t n, const fmi3String categories[]) {
    INSTANCE(c, "fmi3SetDebugLogging");
    (void)n; (void)categories;
    inst->logging = on;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    (void)instantiationToken; (void)resourcePath; (void)visible; (void)requiredIntermediateVariables;
    (void)intermediateUpdate;
    Instance *inst = calloc(1, sizeof(Instance));
    if (!inst) return NULL;
    inst->environment = instanceEnvironment;
    inst->log = logMessage;
    const char *name = instanceName ? instanceName : "";
    inst->name = malloc(strlen(name) + 1);
    if (!inst->name) {
        free(inst);
        return NULL;
    }
    strcpy(inst->name, name);
    inst->logging = loggingOn;
    inst->event_mode_used = eventModeUsed;
    inst->early_return_allowed = earlyReturnAllowed;
    if (nRequiredIntermediateVariables > 0) {
        log_message(inst, fmi3Error, "logStatusError",
                    "fmi3InstantiateCoSimulation: the FMU provides no intermediate update");
        free(inst->name);
        free(inst);
        return NULL;
    }
    defaults(&inst->state);
    return inst;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                               "fmi3InstantiateModelExchange: this is a Co-Simulation FMU only");
    return NULL;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                               "fmi3InstantiateScheduledExecution: this is a Co-Simulation FMU only");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance c) {
    Instance *inst = (Instance *)c;
    if (!inst) return;
    free(inst->name);
    free(inst);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean toleranceDefined, fmi3Float64 tolerance_,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    INSTANCE(c, "fmi3EnterInitializationMode");
    (void)toleranceDefined; (void)tolerance_; (void)stopTimeDefined; (void)stopTime;
    IN_MODE(inst->state.mode == INSTANTIATED, "only after instantiation");
    inst->state.mode = INITIALIZATION;
    inst->state.start = inst->state.time = startTime;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c) {
    INSTANCE(c, "fmi3ExitInitializationMode");
    State *s = &inst->state;
    IN_MODE(s->mode == INITIALIZATION, "only in Initialization Mode");
    if (!(period(s) > 0.0) || !isfinite(period(s))) {
        char problem[200];
        snprintf(problem, sizeof problem, "cycle_period = %g: the clock's interval must be a positive number of "
                 "seconds", period(s));
        s->mode = FAILED;
        return fail(inst, this_function, problem);
    }
    ports_parameters(&s->model, s->values.r, s->values.i, s->values.b);
    s->initialised = 1;
    if (model_init(&s->model)) {
        s->mode = FAILED;
        return fail(inst, this_function, s->model.message);
    }
    s->ticks = 0;
    s->mode = inst->event_mode_used ? EVENT : STEP;
    return fmi3OK;
}

fmi3Status fmi3EnterEventMode(fmi3Instance c) {
    INSTANCE(c, "fmi3EnterEventMode");
    IN_MODE(inst->event_mode_used, "the instance was made with eventModeUsed = false");
    IN_MODE(inst->state.mode == STEP || inst->state.mode == EVENT, "only from Step Mode");
    inst->state.mode = EVENT;
    return fmi3OK;
}

fmi3Status fmi3EnterStepMode(fmi3Instance c) {
    INSTANCE(c, "fmi3EnterStepMode");
    IN_MODE(inst->state.mode == EVENT, "only from Event Mode");
    inst->state.clock = 0;
    inst->state.mode = STEP;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance c) {
    INSTANCE(c, "fmi3Terminate");
    inst->state.mode = TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance c) {
    INSTANCE(c, "fmi3Reset");
    defaults(&inst->state);
    return fmi3OK;
}

/* ---- port values ---- */

/* The slot of value reference vr if it is a variable of the given kind; else -1 and why in `problem`. */
static int checked_slot(const char *function, fmi3ValueReference vr, char kind, char *problem, size_t size) {
    if (vr >= N_VARIABLES) {
        if (vr == CLOCK_VR)
            snprintf(problem, size, "variable cycle (value reference %u) is a Clock: use fmi3GetClock/fmi3SetClock",
                     (unsigned)vr);
        else
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

/* May clocked input vr be set now? Not between ticks when the importer uses Event Mode. */
static int settable(const Instance *inst, fmi3ValueReference vr, char *problem, size_t size) {
    const State *s = &inst->state;
    if (s->mode == TERMINATED || s->mode == FAILED) {
        snprintf(problem, size, "not allowed in %s", mode_name[s->mode]);
        return 0;
    }
    if (port_clocked[vr] != 'i') {
        if (port_clocked[vr] == 'o') {
            snprintf(problem, size, "variable %s is an output", port_name[vr]);
            return 0;
        }
        if (s->mode != INSTANTIATED && s->mode != INITIALIZATION) {
            snprintf(problem, size, "parameter %s is fixed: set it before fmi3ExitInitializationMode", port_name[vr]);
            return 0;
        }
        return 1;
    }
    if (s->mode == INSTANTIATED || s->mode == INITIALIZATION || !inst->event_mode_used) return 1;
    if (s->mode == EVENT && s->clock) return 1;
    snprintf(problem, size, "%s is clocked by cycle: set it in Event Mode while the clock is active (after "
             "fmi3SetClock)", port_name[vr]);
    return 0;
}

#define GET_LOOP(kind, body)                                                                     \
    if (nValues < nValueReferences) return fail(inst, this_function, "fewer values than value references"); \
    for (size_t k = 0; k < nValueReferences; k++) {                                                \
        char problem[240];                                                                        \
        fmi3ValueReference vr = valueReferences[k];                                               \
        int slot = checked_slot(this_function, vr, kind, problem, sizeof problem);                \
        if (slot < 0) return fail(inst, this_function, problem);                                  \
        body;                                                                                     \
    }                                                                                             \
    return fmi3OK

#define SET_LOOP(kind, body)                                                                     \
    if (nValues < nValueReferences) return fail(inst, this_function, "fewer values than value references"); \
    for (size_t k = 0; k < nValueReferences; k++) {                                                \
        char problem[240];                                                                        \
        fmi3ValueReference vr = valueReferences[k];                                               \
        int slot = checked_slot(this_function, vr, kind, problem, sizeof problem);                \
        if (slot < 0 || !settable(inst, vr, problem, sizeof problem)) return fail(inst, this_function, problem); \
        body;                                                                                     \
    }                                                                                             \
    return fmi3OK

fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          fmi3Float64 values[], size_t nValues) {
    INSTANCE(c, "fmi3GetFloat64");
    GET_LOOP('r', values[k] = inst->state.values.r[slot]);
}

fmi3Status fmi3GetInt32(fmi3Instance c, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Int32 values[], size_t nValues) {
    INSTANCE(c, "fmi3GetInt32");
    GET_LOOP('i', values[k] = (fmi3Int32)inst->state.values.i[slot]);
}

fmi3Status fmi3GetBoolean(fmi3Instance c, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          fmi3Boolean values[], size_t nValues) {
    INSTANCE(c, "fmi3GetBoolean");
    GET_LOOP('b', values[k] = inst->state.values.b[slot]);
}

fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          const fmi3Float64 values[], size_t nValues) {
    INSTANCE(c, "fmi3SetFloat64");
    SET_LOOP('r', inst->state.values.r[slot] = values[k]);
}

fmi3Status fmi3SetInt32(fmi3Instance c, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Int32 values[], size_t nValues) {
    INSTANCE(c, "fmi3SetInt32");
    SET_LOOP('i', inst->state.values.i[slot] = values[k]);
}

fmi3Status fmi3SetBoolean(fmi3Instance c, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          const fmi3Boolean values[], size_t nValues) {
    INSTANCE(c, "fmi3SetBoolean");
    SET_LOOP('b', inst->state.values.b[slot] = values[k] != fmi3False);
}

/* The types the FMU has no variables of: any value reference is an error naming what it is. */
#define NO_SUCH_TYPE(getset, Type, ctype)                                                              \
    fmi3Status fmi3##getset##Type(fmi3Instance c, const fmi3ValueReference valueReferences[],          \
                                  size_t nValueReferences, ctype values[], size_t nValues) {           \
        INSTANCE(c, "fmi3" #getset #Type);                                                             \
        (void)values; (void)nValues;                                                                   \
        for (size_t k = 0; k < nValueReferences; k++) {                                                \
            char problem[240];                                                                         \
            checked_slot(this_function, valueReferences[k], '?', problem, sizeof problem);             \
            return fail(inst, this_function, problem);                                                 \
        }                                                                                              \
        return fmi3OK;                                                                                 \
    }

NO_SUCH_TYPE(Get, Float32, fmi3Float32)
NO_SUCH_TYPE(Get, Int8, fmi3Int8)
NO_SUCH_TYPE(Get, UInt8, fmi3UInt8)
NO_SUCH_TYPE(Get, Int16, fmi3Int16)
NO_SUCH_TYPE(Get, UInt16, fmi3UInt16)
NO_SUCH_TYPE(Get, UInt32, fmi3UInt32)
NO_SUCH_TYPE(Get, Int64, fmi3Int64)
NO_SUCH_TYPE(Get, UInt64, fmi3UInt64)
NO_SUCH_TYPE(Get, String, fmi3String)
NO_SUCH_TYPE(Set, Float32, const fmi3Float32)
NO_SUCH_TYPE(Set, Int8, const fmi3Int8)
NO_SUCH_TYPE(Set, UInt8, const fmi3UInt8)
NO_SUCH_TYPE(Set, Int16, const fmi3Int16)
NO_SUCH_TYPE(Set, UInt16, const fmi3UInt16)
NO_SUCH_TYPE(Set, UInt32, const fmi3UInt32)
NO_SUCH_TYPE(Set, Int64, const fmi3Int64)
NO_SUCH_TYPE(Set, UInt64, const fmi3UInt64)
NO_SUCH_TYPE(Set, String, const fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance c, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues) {
    INSTANCE(c, "fmi3GetBinary");
    (void)valueReferences; (void)valueSizes; (void)values; (void)nValues;
    return nValueReferences ? fail(inst, this_function, "the FMU has no Binary variables") : fmi3OK;
}

fmi3Status fmi3SetBinary(fmi3Instance c, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues) {
    INSTANCE(c, "fmi3SetBinary");
    (void)valueReferences; (void)valueSizes; (void)values; (void)nValues;
    return nValueReferences ? fail(inst, this_function, "the FMU has no Binary variables") : fmi3OK;
}

/* ---- the clock ---- */

static int is_clock(Instance *inst, const char *function, fmi3ValueReference vr) {
    if (vr == CLOCK_VR) return 1;
    char problem[240];
    if (vr < N_VARIABLES)
        snprintf(problem, sizeof problem, "variable %s (value reference %u) is not a Clock", port_name[vr], (unsigned)vr);
    else
        snprintf(problem, sizeof problem, "no variable has value reference %u", (unsigned)vr);
    fail(inst, function, problem);
    return 0;
}

fmi3Status fmi3GetClock(fmi3Instance c, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Clock values[]) {
    INSTANCE(c, "fmi3GetClock");
    for (size_t k = 0; k < nValueReferences; k++) {
        if (!is_clock(inst, this_function, valueReferences[k])) return fmi3Error;
        values[k] = inst->state.clock ? fmi3ClockActive : fmi3ClockInactive;
    }
    return fmi3OK;
}

fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Clock values[]) {
    INSTANCE(c, "fmi3SetClock");
    IN_MODE(inst->state.mode == EVENT, "input clocks are activated in Event Mode");
    for (size_t k = 0; k < nValueReferences; k++) {
        if (!is_clock(inst, this_function, valueReferences[k])) return fmi3Error;
        inst->state.clock = values[k] ? 1 : 0;
    }
    return fmi3OK;
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance c, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                                  fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[]) {
    INSTANCE(c, "fmi3GetIntervalDecimal");
    for (size_t k = 0; k < nValueReferences; k++) {
        if (!is_clock(inst, this_function, valueReferences[k])) return fmi3Error;
        intervals[k] = period(&inst->state);
        qualifiers[k] = inst->state.mode == INITIALIZATION || inst->state.mode == INSTANTIATED ? fmi3IntervalChanged
                                                                                               : fmi3IntervalUnchanged;
    }
    return fmi3OK;
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance c, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                               fmi3Float64 shifts[]) {
    INSTANCE(c, "fmi3GetShiftDecimal");
    for (size_t k = 0; k < nValueReferences; k++) {
        if (!is_clock(inst, this_function, valueReferences[k])) return fmi3Error;
        shifts[k] = 0.0;
    }
    return fmi3OK;
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance c, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[]) {
    INSTANCE(c, "fmi3GetIntervalFraction");
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions; (void)qualifiers;
    return fail(inst, this_function, "the clock does not support fractions (use fmi3GetIntervalDecimal)");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance c, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
    INSTANCE(c, "fmi3GetShiftFraction");
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    return fail(inst, this_function, "the clock does not support fractions (use fmi3GetShiftDecimal)");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance c, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                                  const fmi3Float64 intervals[]) {
    INSTANCE(c, "fmi3SetIntervalDecimal");
    (void)valueReferences; (void)nValueReferences; (void)intervals;
    return fail(inst, this_function, "the clock's interval is the parameter cycle_period: set that instead");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance c, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    INSTANCE(c, "fmi3SetIntervalFraction");
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    return fail(inst, this_function, "the clock's interval is the parameter cycle_period: set that instead");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance c, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                               const fmi3Float64 shifts[]) {
    INSTANCE(c, "fmi3SetShiftDecimal");
    (void)valueReferences; (void)nValueReferences; (void)shifts;
    return fail(inst, this_function, "the clock's shift is 0");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance c, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    INSTANCE(c, "fmi3SetShiftFraction");
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    return fail(inst, this_function, "the clock's shift is 0");
}

/* ---- cycles ---- */

/* The model computes in int64; an FMI Int32 port beyond its range is an error naming the port. */
static int integers_fit(State *s) {
    for (int v = 0; v < N_VARIABLES; v++) {
        if (port_kind[v] != 'i') continue;
        int64_t x = s->values.i[port_slot[v]];
        if (x < INT32_MIN || x > INT32_MAX) {
            snprintf(s->model.message, sizeof s->model.message,
                     "port %s = %lld does not fit an FMI Int32 (cycle %lld)", port_name[v], (long long)x,
                     (long long)s->model.cycle);
            return 0;
        }
    }
    return 1;
}

/* One cycle: inputs in (input events only if `events`), the model's cycle, outputs out; nonzero on error. */
static int run_cycle(State *s, int events) {
    ports_to_model(&s->model, s->values.r, s->values.i, s->values.b);
    if (!events) ports_clear_input_events(&s->model);
    if (model_step(&s->model)) return 1;
    ports_from_model(&s->model, s->values.r, s->values.i, s->values.b);
    return N_INTEGER > 0 && !integers_fit(s);
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    INSTANCE(c, "fmi3UpdateDiscreteStates");
    State *s = &inst->state;
    IN_MODE(s->mode == EVENT, "only in Event Mode");
    if (s->clock) {  /* a tick: one cycle, its input events consumed by it */
        ports_clear_outputs(s->values.r, s->values.i, s->values.b);
        if (run_cycle(s, 1)) {
            s->mode = FAILED;
            return fail(inst, this_function, s->model.message);
        }
        ports_clear_input_flags(s->values.b);
        s->clock = 0;
        s->ticks = (int64_t)floor((s->time - s->start) / period(s) + 1e-9) + 1;
    }
    if (discreteStatesNeedUpdate) *discreteStatesNeedUpdate = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (nominalsOfContinuousStatesChanged) *nominalsOfContinuousStatesChanged = fmi3False;
    if (valuesOfContinuousStatesChanged) *valuesOfContinuousStatesChanged = fmi3False;
    if (nextEventTimeDefined) *nextEventTimeDefined = fmi3True;
    if (nextEventTime) *nextEventTime = tick_time(s, s->ticks);
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    INSTANCE(c, "fmi3DoStep");
    (void)noSetFMUStatePriorToCurrentPoint;
    State *s = &inst->state;
    IN_MODE(s->mode == STEP, "only in Step Mode");
    double t = currentCommunicationPoint, end = t + communicationStepSize;
    if (!(communicationStepSize > 0.0)) return fail(inst, this_function, "the step size must be positive");
    s->time = t;
    double eps = tolerance(s);
    int early = 0, event = 0;
    if (!inst->event_mode_used) {  /* the FMU handles its clock: a cycle per tick in [t, end) */
        ports_clear_outputs(s->values.r, s->values.i, s->values.b);
        int first = 1;
        while (tick_time(s, s->ticks) < end - eps) {
            if (run_cycle(s, first)) {
                s->mode = FAILED;
                return fail(inst, this_function, s->model.message);
            }
            first = 0;
            s->ticks++;
        }
    } else {
        double next = tick_time(s, s->ticks);
        if (next < t - eps || fabs(next - t) <= eps) {
            char problem[300];
            snprintf(problem, sizeof problem, "the clock's tick at t = %.9g s was not activated: enter Event Mode "
                     "there, fmi3SetClock(cycle) and fmi3UpdateDiscreteStates", next);
            s->mode = FAILED;
            return fail(inst, this_function, problem);
        }
        if (next < end - eps) {
            if (!inst->early_return_allowed) {
                char problem[300];
                snprintf(problem, sizeof problem, "the step from %.9g s to %.9g s passes the clock's tick at %.9g s "
                         "(cycle_period %.9g s): step to the tick and handle it in Event Mode", t, end, next,
                         period(s));
                return fail(inst, this_function, problem);
            }
            end = next;
            early = 1;
            event = 1;
        } else if (fabs(next - end) <= eps) {
            event = 1;
        }
    }
    s->time = end;
    if (eventHandlingNeeded) *eventHandlingNeeded = event ? fmi3True : fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = early ? fmi3True : fmi3False;
    if (lastSuccessfulTime) *lastSuccessfulTime = end;
    return fmi3OK;
}

/* ---- FMU state: a tagged copy of the instance's State ---- */

fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState *FMUState) {
    INSTANCE(c, "fmi3GetFMUState");
    if (!FMUState) return fail(inst, this_function, "no place for the state (NULL)");
    State *copy = (State *)*FMUState;
    if (!copy) copy = malloc(sizeof(State));
    if (!copy) return fail(inst, this_function, "out of memory");
    memcpy(copy, &inst->state, sizeof(State));
    *FMUState = copy;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState FMUState) {
    INSTANCE(c, "fmi3SetFMUState");
    const State *saved = (const State *)FMUState;
    if (!saved) return fail(inst, this_function, "no state (NULL)");
    if (saved->tag != (STATE_TAG ^ FMI3_TAG)) return fail(inst, this_function, "the state belongs to another FMU");
    memcpy(&inst->state, saved, sizeof(State));
    return fmi3OK;
}

fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState *FMUState) {
    INSTANCE(c, "fmi3FreeFMUState");
    if (FMUState) {
        free(*FMUState);
        *FMUState = NULL;
    }
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState FMUState, size_t *size) {
    INSTANCE(c, "fmi3SerializedFMUStateSize");
    if (!FMUState || !size) return fail(inst, this_function, "no state or no place for its size (NULL)");
    *size = sizeof(State);
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance c, fmi3FMUState FMUState, fmi3Byte serializedState[], size_t size) {
    INSTANCE(c, "fmi3SerializeFMUState");
    if (!FMUState || !serializedState) return fail(inst, this_function, "no state or no buffer (NULL)");
    if (size < sizeof(State)) return fail(inst, this_function, "the buffer is smaller than fmi3SerializedFMUStateSize");
    memcpy(serializedState, FMUState, sizeof(State));
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance c, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState) {
    INSTANCE(c, "fmi3DeserializeFMUState");
    if (!serializedState || !FMUState) return fail(inst, this_function, "no bytes or no place for the state (NULL)");
    uint64_t tag;
    if (size != sizeof(State)) return fail(inst, this_function, "the bytes are not a state of this FMU (wrong size)");
    memcpy(&tag, serializedState, sizeof tag);
    if (tag != (STATE_TAG ^ FMI3_TAG)) return fail(inst, this_function, "the bytes are a state of another FMU");
    State *copy = (State *)*FMUState;
    if (!copy) copy = malloc(sizeof(State));
    if (!copy) return fail(inst, this_function, "out of memory");
    memcpy(copy, serializedState, sizeof(State));
    *FMUState = copy;
    return fmi3OK;
}

/* ---- what a discrete Co-Simulation FMU does not provide ---- */

#define UNSUPPORTED(name, params, unused, why)          \
    fmi3Status name params {                            \
        INSTANCE(instance, #name);                      \
        unused;                                         \
        return fail(inst, this_function, why);          \
    }

UNSUPPORTED(fmi3GetNumberOfVariableDependencies, (fmi3Instance instance, fmi3ValueReference valueReference,
            size_t *nDependencies), (void)valueReference; (void)nDependencies,
            "no dependency information beyond the model description")
UNSUPPORTED(fmi3GetVariableDependencies, (fmi3Instance instance, fmi3ValueReference dependent,
            size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
            size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[], size_t nDependencies),
            (void)dependent; (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
            (void)dependencyKinds; (void)nDependencies, "no dependency information beyond the model description")
UNSUPPORTED(fmi3GetDirectionalDerivative, (fmi3Instance instance, const fmi3ValueReference unknowns[],
            size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
            size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity),
            (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
            (void)nSensitivity, "the FMU provides no directional derivatives")
UNSUPPORTED(fmi3GetAdjointDerivative, (fmi3Instance instance, const fmi3ValueReference unknowns[],
            size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
            size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity),
            (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
            (void)nSensitivity, "the FMU provides no adjoint derivatives")
UNSUPPORTED(fmi3EnterConfigurationMode, (fmi3Instance instance), (void)0, "the FMU has no structural parameters")
UNSUPPORTED(fmi3ExitConfigurationMode, (fmi3Instance instance), (void)0, "the FMU has no structural parameters")
UNSUPPORTED(fmi3EvaluateDiscreteStates, (fmi3Instance instance), (void)0, "a Model Exchange function")
UNSUPPORTED(fmi3EnterContinuousTimeMode, (fmi3Instance instance), (void)0, "a Model Exchange function")
UNSUPPORTED(fmi3CompletedIntegratorStep, (fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
            fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation),
            (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation,
            "a Model Exchange function")
UNSUPPORTED(fmi3SetTime, (fmi3Instance instance, fmi3Float64 time), (void)time, "a Model Exchange function")
UNSUPPORTED(fmi3SetContinuousStates, (fmi3Instance instance, const fmi3Float64 continuousStates[],
            size_t nContinuousStates), (void)continuousStates; (void)nContinuousStates, "a Model Exchange function")
UNSUPPORTED(fmi3GetContinuousStateDerivatives, (fmi3Instance instance, fmi3Float64 derivatives[],
            size_t nContinuousStates), (void)derivatives; (void)nContinuousStates, "a Model Exchange function")
UNSUPPORTED(fmi3GetEventIndicators, (fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators),
            (void)eventIndicators; (void)nEventIndicators, "a Model Exchange function")
UNSUPPORTED(fmi3GetContinuousStates, (fmi3Instance instance, fmi3Float64 continuousStates[],
            size_t nContinuousStates), (void)continuousStates; (void)nContinuousStates, "a Model Exchange function")
UNSUPPORTED(fmi3GetNominalsOfContinuousStates, (fmi3Instance instance, fmi3Float64 nominals[],
            size_t nContinuousStates), (void)nominals; (void)nContinuousStates, "a Model Exchange function")
UNSUPPORTED(fmi3GetNumberOfEventIndicators, (fmi3Instance instance, size_t *nEventIndicators),
            (void)nEventIndicators, "a Model Exchange function")
UNSUPPORTED(fmi3GetNumberOfContinuousStates, (fmi3Instance instance, size_t *nContinuousStates),
            (void)nContinuousStates, "a Model Exchange function")
UNSUPPORTED(fmi3GetOutputDerivatives, (fmi3Instance instance, const fmi3ValueReference valueReferences[],
            size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues),
            (void)valueReferences; (void)nValueReferences; (void)orders; (void)values; (void)nValues,
            "the FMU's outputs are discrete: no derivatives")
UNSUPPORTED(fmi3ActivateModelPartition, (fmi3Instance instance, fmi3ValueReference clockReference,
            fmi3Float64 activationTime), (void)clockReference; (void)activationTime,
            "a Scheduled Execution function")
