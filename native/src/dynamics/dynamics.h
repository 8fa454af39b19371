/* Newton-Euler integration with the implicit finger coupling (dynamics.c), above the body
 * layer and xFCA (it reads the finger contacts xFCA left). */
#ifndef GC_DYNAMICS_H
#define GC_DYNAMICS_H

#include "world/body.h"

/* In step order: new velocities of every dynamic body under gravity, the gyroscopic term
 * and the implicit finger coupling (leaves each body's effective mass); then, after the
 * contacts, positions (and the non-finite guard). */
void gc_dynamics_velocities(gcWorld *world, double dt);
void gc_dynamics_positions(gcWorld *world, double dt);

#endif
