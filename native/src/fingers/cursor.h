/* The light-mass haptic cursor (cursor.c): a finger renderer beside xFCA, above geometry. */
#ifndef GC_CURSOR_H
#define GC_CURSOR_H

#include "world/body.h"
#include "geometry/geometry.h"

/* One tick of a cursor finger (start of a step, on the current poses): its free motion,
 * the constraint solve against every convex part in reach, friction; its contacts. */
void gc_cursor_finger_update(gcWorld *world, int32_t finger, double dt);
/* Its force and reported god-object (the cursor), at the end of a step. */
void gc_cursor_finger_outputs(gcWorld *world, int32_t finger);

#endif
