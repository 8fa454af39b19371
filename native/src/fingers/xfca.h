/* xFCA, the friction-cone god-object algorithm (xfca.c), above the body layer, geometry and
 * the cursor renderer (cursor.c), to which it hands the fingers that use it. */
#ifndef GC_XFCA_H
#define GC_XFCA_H

#include "world/body.h"

/* One god-object update for every finger (start of a step, on the current poses). */
void gc_xfca_update(gcWorld *world, double dt);
/* Finger forces and reported god-objects, at the end of a step: on the poses the bodies
 * moved to, so a fingertip carrying a body feels the spring the body felt (no one-step
 * lag of k v dt against the motion). */
void gc_xfca_outputs(gcWorld *world);

#endif
