/* A generated test case as an FMI 2.0 co-simulation FMU: the test driver the paper asks for.
 *
 * The same for every case; what differs is case.h (cotwin.dmodel.testgen_driver): the ports, and per
 * cycle the inputs the case sends (`send`) and what the d-model must do (`check`).
 *
 * Connected to a d-model FMU port to port under a Jacobi master with one d-model cycle per step (Maestro's
 * default, the paper's set-up): the driver's outputs after initialisation are the inputs of cycle 1;
 * its step k (k = 0, 1, ...) first checks the d-model's outputs it reads, those of cycle k (k >= 1),
 * then shows the inputs of cycle k + 2 (which the d-model takes in its step k + 1). `verdict` is 0 while
 * the case runs, 1 once every cycle was as the oracle says, -1 at the first difference (`divergence_cycle`
 * says where; the FMU logs what differed, and keeps the verdict).
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "case.h"

#define SLOTS(n) ((n) > 0 ? (n) : 1)

typedef struct {
    double r[SLOTS(N_REAL)];
    int i[SLOTS(N_INTEGER)];
    int b[SLOTS(N_BOOLEAN)];
    int step;
    int verdict, divergence, initialised;
    char why[400];
    fmi2CallbackFunctions functions;
    char *name;
} Instance;

static void log_message(Instance *inst, fmi2Status status, const char *category, const char *message) {
    if (inst->functions.logger)
        inst->functions.logger(inst->functions.componentEnvironment, inst->name ? inst->name : "", status, category,
                               "%s", message);
}

static fmi2Status fail(Instance *inst, const char *function, const char *detail) {
    char text[480];
    snprintf(text, sizeof text, "%s: %s", function, detail);
    log_message(inst, fmi2Error, "logStatusError", text);
    return fmi2Error;
}

static int near(double a, double b) { return a == b || fabs(a - b) <= 1e-9 * fmax(1.0, fmax(fabs(a), fabs(b))); }

static void publish(Instance *inst) {
    inst->i[VERDICT_SLOT] = inst->verdict;
    inst->i[DIVERGENCE_SLOT] = inst->divergence;
    inst->i[CYCLE_SLOT] = inst->step;
}

#define INSTANCE(c)                      \
    Instance *inst = (Instance *)(c);    \
    if (!inst) return fmi2Error

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)fmuGUID; (void)fmuResourceLocation; (void)visible; (void)loggingOn;
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
    return inst;
}

void fmi2FreeInstance(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (!inst) return;
    free(inst->name);
    free(inst);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String categories[]) {
    INSTANCE(c);
    (void)on; (void)n; (void)categories;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    INSTANCE(c);
    (void)toleranceDefined; (void)tolerance; (void)startTime; (void)stopTimeDefined; (void)stopTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    INSTANCE(c);
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    INSTANCE(c);
    send(1, inst->r, inst->i, inst->b);
    inst->initialised = 1;
    publish(inst);
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    INSTANCE(c);
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    INSTANCE(c);
    Instance keep = *inst;
    memset(inst, 0, sizeof *inst);
    inst->functions = keep.functions;
    inst->name = keep.name;
    return fmi2OK;
}

static int slot_of(fmi2ValueReference vr, char kind) {
    return vr < N_VARIABLES && port_kind[vr] == kind ? port_slot[vr] : -1;
}

#define PORT_LOOP(kind, name, body)                                                              \
    for (size_t k = 0; k < n; k++) {                                                              \
        int slot = slot_of(vr[k], kind);                                                          \
        if (slot < 0) {                                                                           \
            char problem[120];                                                                    \
            snprintf(problem, sizeof problem, "no variable of this type has value reference %u", (unsigned)vr[k]); \
            return fail(inst, name, problem);                                                     \
        }                                                                                         \
        body;                                                                                     \
    }                                                                                             \
    return fmi2OK

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    INSTANCE(c);
    PORT_LOOP('r', "fmi2GetReal", value[k] = inst->r[slot]);
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer value[]) {
    INSTANCE(c);
    PORT_LOOP('i', "fmi2GetInteger", value[k] = inst->i[slot]);
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean value[]) {
    INSTANCE(c);
    PORT_LOOP('b', "fmi2GetBoolean", value[k] = inst->b[slot] ? fmi2True : fmi2False);
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    INSTANCE(c);
    PORT_LOOP('r', "fmi2SetReal", inst->r[slot] = value[k]);
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer value[]) {
    INSTANCE(c);
    PORT_LOOP('i', "fmi2SetInteger", inst->i[slot] = value[k]);
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean value[]) {
    INSTANCE(c);
    PORT_LOOP('b', "fmi2SetBoolean", inst->b[slot] = value[k] != fmi2False);
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String value[]) {
    INSTANCE(c);
    (void)vr; (void)value;
    return n ? fail(inst, "fmi2GetString", "the FMU has no String variables") : fmi2OK;
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String value[]) {
    INSTANCE(c);
    (void)vr; (void)value;
    return n ? fail(inst, "fmi2SetString", "the FMU has no String variables") : fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    INSTANCE(c);
    (void)currentCommunicationPoint; (void)communicationStepSize; (void)noSetFMUStatePriorToCurrentPoint;
    if (!inst->initialised) return fail(inst, "fmi2DoStep", "not initialised (fmi2ExitInitializationMode)");
    int k = inst->step;
    if (k >= 1 && k <= N_CYCLES && inst->verdict == 0) {
        if (!check(k, inst->r, inst->i, inst->b, near, inst->why, sizeof inst->why)) {
            inst->verdict = -1;
            inst->divergence = k;
            log_message(inst, fmi2Warning, "logVerdict", inst->why);
        } else if (k == N_CYCLES) {
            inst->verdict = 1;
        }
    }
    send(k + 2, inst->r, inst->i, inst->b);
    inst->step = k + 1;
    publish(inst);
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    INSTANCE(c);
    return fail(inst, "fmi2CancelStep", "steps complete synchronously");
}

#define NO_STATUS(name, type)                                                        \
    fmi2Status name(fmi2Component c, const fmi2StatusKind s, type *value) {         \
        (void)c; (void)s; (void)value;                                               \
        return fmi2Discard;                                                          \
    }
NO_STATUS(fmi2GetStatus, fmi2Status)
NO_STATUS(fmi2GetRealStatus, fmi2Real)
NO_STATUS(fmi2GetIntegerStatus, fmi2Integer)
NO_STATUS(fmi2GetBooleanStatus, fmi2Boolean)
NO_STATUS(fmi2GetStringStatus, fmi2String)

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    INSTANCE(c);
    (void)vr; (void)n; (void)order; (void)value;
    return fail(inst, "fmi2SetRealInputDerivatives", "the FMU does not interpolate inputs");
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real value[]) {
    INSTANCE(c);
    (void)vr; (void)n; (void)order; (void)value;
    return fail(inst, "fmi2GetRealOutputDerivatives", "the FMU has no output derivatives");
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference unknown[], size_t nUnknown,
                                        const fmi2ValueReference known[], size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    INSTANCE(c);
    (void)unknown; (void)nUnknown; (void)known; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    return fail(inst, "fmi2GetDirectionalDerivative", "the FMU provides no derivatives");
}
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) {
    INSTANCE(c);
    (void)s;
    return fail(inst, "fmi2GetFMUstate", "a test driver does not save its state");
}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) {
    INSTANCE(c);
    (void)s;
    return fail(inst, "fmi2SetFMUstate", "a test driver does not restore a state");
}
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) {
    INSTANCE(c);
    (void)s;
    return fmi2OK;
}
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *size) {
    INSTANCE(c);
    (void)s; (void)size;
    return fail(inst, "fmi2SerializedFMUstateSize", "a test driver does not save its state");
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte bytes[], size_t size) {
    INSTANCE(c);
    (void)s; (void)bytes; (void)size;
    return fail(inst, "fmi2SerializeFMUstate", "a test driver does not save its state");
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *s) {
    INSTANCE(c);
    (void)bytes; (void)size; (void)s;
    return fail(inst, "fmi2DeSerializeFMUstate", "a test driver does not restore a state");
}
