/* The internal step (step.c), above dynamics, contacts and xFCA, below the runtime and the
 * world API. */
#ifndef GC_STEP_H
#define GC_STEP_H

#include "contacts/contacts.h"
#include "dynamics.h"
#include "fingers/xfca.h"

/* The body phase: velocities, contacts, positions. Only the bodies of world->body_active
 * move when it is set (a runtime shadow). Returns how many bodies the non-finite guard
 * stopped in this step (first one: world->first_stopped_body). */
int gc_step_bodies(gcWorld *world, double dt);
/* A whole step of dt: xFCA update, gc_step_bodies, finger outputs, HIP history, time. */
int gc_step(gcWorld *world, double dt);

#endif
