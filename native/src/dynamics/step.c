/* The one step, shared by gc_world_step and the runtime's loops (which step their own
 * shadow worlds): god-objects on the current poses, body velocities under gravity and the
 * implicit finger springs, body-body contacts through those effective masses, positions,
 * then the forces the fingers feel on the poses the bodies reached. */
#include "step.h"

int gc_step_bodies(gcWorld *w, double dt) {
    w->step_stopped_bodies = 0;
    gc_dynamics_velocities(w, dt);
    gc_contacts_step(w, dt);
    gc_dynamics_positions(w, dt);
    return w->step_stopped_bodies;
}

int gc_step(gcWorld *w, double dt) {
    const gcModel *model = w->model;
    gc_xfca_update(w, dt);
    int stopped = gc_step_bodies(w, dt);
    gc_xfca_outputs(w);
    for (int i = 0; i < w->num_fingers; ++i) {
        gcFinger *f = &w->fingers[i];
        f->hip_prev = f->hip;
        if (model->fingers[i].num_vertices) f->q_prev = f->q, f->R_prev = f->R; /* a convex finger's turn per step */
    }
    w->time += dt;
    return stopped;
}
