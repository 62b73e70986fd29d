/* The appendix A state feedback (../c/appendix_sf.c, the law the C client and the firmware run) as an FMI 3.0
 * co-simulation unit: a controller any importer can step, ballbeam's `--controller fmu:BbStateFeedback.fmu`
 * included.
 *
 * Variables (modelDescription.xml): inputs ball_v and angle_v (the card's two readings, V), output dac_v (the
 * DAC command, V). Each doStep consumes the inputs set before it: the first starts the law on them (the held
 * rig's block, the software's Start) and leaves the zero command out; each later one is a Drive Motor tick,
 * its command out after the step. The calibration is the rig software's (../avr/rig.h, checked against the
 * twin's parameters). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "appendix_sf.h"
#include "fmi3Functions.h"
#include "rig.h"

enum { VR_TIME = 0, VR_BALL = 1, VR_ANGLE = 2, VR_DAC = 3 };

typedef struct {
    sf_state law;
    int started;
    double time, ball_v, angle_v, dac_v;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
    char name[64];
} bb_instance;

static void say(bb_instance *b, fmi3Status status, const char *message)
{
    if (b->log) b->log(b->env, status, "logStatusError", message);
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean on, size_t n, const fmi3String categories[])
{
    (void)instance, (void)on, (void)n, (void)categories;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String name, fmi3String token, fmi3String resources,
                                         fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference required[], size_t nRequired,
                                         fmi3InstanceEnvironment env, fmi3LogMessageCallback log,
                                         fmi3IntermediateUpdateCallback update)
{
    (void)token, (void)resources, (void)visible, (void)loggingOn, (void)eventModeUsed;
    (void)earlyReturnAllowed, (void)required, (void)nRequired, (void)update;
    bb_instance *b = calloc(1, sizeof *b);
    if (!b) return NULL;
    b->env = env;
    b->log = log;
    snprintf(b->name, sizeof b->name, "%s", name ? name : "");
    b->dac_v = RIG_COMMAND_ZERO_V;
    return b;
}

void fmi3FreeInstance(fmi3Instance instance) { free(instance); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    (void)toleranceDefined, (void)tolerance, (void)stopTimeDefined, (void)stopTime;
    ((bb_instance *)instance)->time = startTime;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    (void)instance;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    (void)instance;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    bb_instance *b = instance;
    memset(&b->law, 0, sizeof b->law);
    b->started = 0;
    b->time = b->ball_v = b->angle_v = 0.0;
    b->dac_v = RIG_COMMAND_ZERO_V;
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues)
{
    bb_instance *b = instance;
    if (nValues < nvr) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) {
        switch (vr[i]) {
        case VR_TIME: values[i] = b->time; break;
        case VR_BALL: values[i] = b->ball_v; break;
        case VR_ANGLE: values[i] = b->angle_v; break;
        case VR_DAC: values[i] = b->dac_v; break;
        default: say(b, fmi3Error, "fmi3GetFloat64: unknown value reference"); return fmi3Error;
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues)
{
    bb_instance *b = instance;
    if (nValues < nvr) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) {
        switch (vr[i]) {
        case VR_BALL: b->ball_v = values[i]; break;
        case VR_ANGLE: b->angle_v = values[i]; break;
        default: say(b, fmi3Error, "fmi3SetFloat64: only ball_v and angle_v are inputs"); return fmi3Error;
        }
    }
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    bb_instance *b = instance;
    static const sf_calibration cal = RIG_SF_CALIBRATION;
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    if (!b->started) {
        if (sf_start(&b->law, &cal, b->ball_v, b->angle_v) != 0) {
            say(b, fmi3Error, "the start block's volts are not finite");
            return fmi3Error;
        }
        b->started = 1;
        b->dac_v = RIG_COMMAND_ZERO_V;
    } else if (sf_update(&b->law, b->ball_v, b->angle_v, &b->dac_v) != 0) {
        say(b, fmi3Error, "a block's volts or the command are not finite");
        return fmi3Error;
    }
    b->time = currentCommunicationPoint + communicationStepSize;
    *lastSuccessfulTime = b->time;
    return fmi3OK;
}
