/* The Grasp Lab device protocol's codec (device_codec.c, docs/protocol.md): CRC, COBS, frames,
 * a streaming decoder and little-endian payload fields. No world types, no threads. */
#ifndef GC_DEVICE_CODEC_H
#define GC_DEVICE_CODEC_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#define GC_PROTO_VERSION 1
#define GC_PROTO_MAX_FINGERS 32
#define GC_PROTO_HEADER 4
#define GC_PROTO_POSE_FINGER 12          /* f32 x, y, z */
#define GC_PROTO_ORIENTED_FINGER 28      /* f32 x, y, z, then f32 w, x, y, z (HELLO_DEVICE flags bit 1) */
/* The largest frame: a POSE of 32 fingers with orientations (a FORCE of 32 is 396 bytes). */
#define GC_PROTO_BODY_MAX (GC_PROTO_HEADER + 6 + GC_PROTO_ORIENTED_FINGER * GC_PROTO_MAX_FINGERS + 2)
#define GC_PROTO_WIRE_MAX (GC_PROTO_BODY_MAX + GC_PROTO_BODY_MAX / 254 + 1) /* delimiter excluded */
#define GC_PROTO_NAME_MAX 32

enum {
    GC_MSG_HELLO_HOST = 0x01,
    GC_MSG_HELLO_DEVICE = 0x02,
    GC_MSG_POSE = 0x03,
    GC_MSG_FORCE = 0x04,
    GC_MSG_ENABLE = 0x05,
    GC_MSG_ESTOP = 0x06,
    GC_MSG_HEARTBEAT = 0x07
};
enum { GC_CAP_FORCES = 0x01, GC_CAP_ORIENTATION = 0x02 };
/* FORCE byte 5: the host takes this device's orientations (it may send them from now on). */
enum { GC_FORCE_TAKES_ORIENTATION = 0x01 };
enum { GC_STATUS_FORCES_ON = 0x01, GC_STATUS_ESTOPPED = 0x02, GC_STATUS_GRIP = 0x04 };

/* Why a frame was dropped; the order of protocol.py's StreamDecoder.KINDS, then range. */
typedef enum gcFrameError {
    GC_FRAME_OK = -1,
    GC_FRAME_COBS = 0,
    GC_FRAME_SHORT,
    GC_FRAME_CRC,
    GC_FRAME_VERSION,
    GC_FRAME_TYPE,
    GC_FRAME_LENGTH,
    GC_FRAME_OVERFLOW,
    GC_FRAME_RANGE, /* payload: NaN/Inf, out of the workspace, a finger count that is not the device's */
    GC_FRAME_KINDS
} gcFrameError;

typedef struct gcFrame {
    uint8_t type;
    uint16_t seq;
    size_t len; /* payload bytes */
    uint8_t payload[GC_PROTO_BODY_MAX];
} gcFrame;

/* CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor). */
uint16_t gc_crc16(const uint8_t *data, size_t n);
/* out holds n + n / 254 + 1 bytes; returns the encoded length (no zero byte in it). */
size_t gc_cobs_encode(const uint8_t *in, size_t n, uint8_t *out);
/* 0 and *out_n on success, -1 on a malformed encoding or when it needs more than cap bytes. */
int gc_cobs_decode(const uint8_t *in, size_t n, uint8_t *out, size_t cap, size_t *out_n);
/* A frame on the wire with its delimiter, into out (GC_PROTO_WIRE_MAX + 1 bytes); 0 when
 * the payload is too long. */
size_t gc_frame_encode(uint8_t type, uint16_t seq, const uint8_t *payload, size_t n, uint8_t *out);
/* One frame from its encoding (delimiter excluded): GC_FRAME_OK, or why it is invalid. */
gcFrameError gc_frame_decode(const uint8_t *wire, size_t n, gcFrame *out);

/* Streaming decoder: bytes in, frames out; resynchronises on the next zero after an error. */
typedef struct gcFrameDecoder {
    uint8_t buf[GC_PROTO_WIRE_MAX];
    size_t len;
    int overflow;
    uint64_t frames;
    uint64_t errors[GC_FRAME_KINDS];
} gcFrameDecoder;
void gc_decoder_reset(gcFrameDecoder *d);
/* 1 when this byte completed a valid frame (in *out); errors are counted in d->errors. */
int gc_decoder_push(gcFrameDecoder *d, uint8_t byte, gcFrame *out);

/* A valid POSE frame's payload carries an orientation a finger (after the positions). */
static inline int gc_pose_has_orientations(const gcFrame *fr) {
    return fr->len >= 6 && fr->payload[4] > 0 && fr->len == 6 + (size_t)GC_PROTO_ORIENTED_FINGER * fr->payload[4];
}

/* Little-endian field access for payloads. */
static inline uint16_t gc_le16(const uint8_t *p) { return (uint16_t)(p[0] | p[1] << 8); }
static inline uint32_t gc_le32(const uint8_t *p) {
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}
static inline float gc_lef32(const uint8_t *p) {
    uint32_t u = gc_le32(p);
    float f;
    memcpy(&f, &u, 4);
    return f;
}
static inline void gc_put16(uint8_t *p, uint16_t v) { p[0] = (uint8_t)v, p[1] = (uint8_t)(v >> 8); }
static inline void gc_put32(uint8_t *p, uint32_t v) {
    for (int i = 0; i < 4; ++i) p[i] = (uint8_t)(v >> (8 * i));
}
static inline void gc_putf32(uint8_t *p, float f) {
    uint32_t u;
    memcpy(&u, &f, 4);
    gc_put32(p, u);
}

#endif
