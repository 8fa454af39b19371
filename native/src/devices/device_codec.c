/* The device protocol's codec (device_codec.h, docs/protocol.md). */
#include "device_codec.h"

uint16_t gc_crc16(const uint8_t *data, size_t n) {
    uint16_t crc = 0xFFFF;
    for (size_t i = 0; i < n; ++i) {
        crc ^= (uint16_t)(data[i] << 8);
        for (int b = 0; b < 8; ++b) crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
    }
    return crc;
}

size_t gc_cobs_encode(const uint8_t *in, size_t n, uint8_t *out) {
    size_t code_at = 0, o = 1;
    uint8_t code = 1;
    int full = 0; /* the input so far ends with a full 254-byte block: no final block */
    for (size_t i = 0; i < n; ++i) {
        full = 0;
        if (in[i] == 0) {
            out[code_at] = code;
            code_at = o++;
            code = 1;
            continue;
        }
        out[o++] = in[i];
        if (++code == 0xFF) {
            out[code_at] = code;
            code_at = o++;
            code = 1;
            full = 1;
        }
    }
    if (full) return o - 1;
    out[code_at] = code;
    return o;
}

int gc_cobs_decode(const uint8_t *in, size_t n, uint8_t *out, size_t cap, size_t *out_n) {
    size_t i = 0, o = 0;
    while (i < n) {
        uint8_t code = in[i];
        if (code == 0 || i + code > n) return -1;
        for (size_t k = i + 1; k < i + code; ++k) {
            if (in[k] == 0 || o == cap) return -1;
            out[o++] = in[k];
        }
        i += code;
        if (code != 0xFF && i < n) {
            if (o == cap) return -1;
            out[o++] = 0;
        }
    }
    *out_n = o;
    return 0;
}

size_t gc_frame_encode(uint8_t type, uint16_t seq, const uint8_t *payload, size_t n, uint8_t *out) {
    uint8_t body[GC_PROTO_BODY_MAX];
    if (GC_PROTO_HEADER + n + 2 > sizeof body) return 0;
    body[0] = GC_PROTO_VERSION;
    body[1] = type;
    gc_put16(body + 2, seq);
    if (n) memcpy(body + GC_PROTO_HEADER, payload, n);
    size_t len = GC_PROTO_HEADER + n;
    gc_put16(body + len, gc_crc16(body, len));
    len += 2;
    size_t w = gc_cobs_encode(body, len, out);
    out[w] = 0;
    return w + 1;
}

/* Payload length the type requires (pose and force: by the finger count they carry). */
static int payload_length_ok(uint8_t type, const uint8_t *p, size_t n) {
    switch (type) {
    case GC_MSG_HELLO_HOST: return n == 2;
    case GC_MSG_HELLO_DEVICE: return n >= 12 && n <= 12 + GC_PROTO_NAME_MAX;
    case GC_MSG_POSE: /* positions, or positions then orientations (the device's hello says which it may send) */
        return n >= 6 && ((size_t)p[4] * GC_PROTO_POSE_FINGER == n - 6 || (size_t)p[4] * GC_PROTO_ORIENTED_FINGER == n - 6);
    case GC_MSG_FORCE: return n >= 6 && (size_t)p[4] * 12 == n - 6;
    case GC_MSG_ENABLE:
    case GC_MSG_ESTOP: return n == 1;
    case GC_MSG_HEARTBEAT: return n == 4;
    default: return 0;
    }
}

gcFrameError gc_frame_decode(const uint8_t *wire, size_t n, gcFrame *out) {
    uint8_t body[GC_PROTO_BODY_MAX];
    size_t len;
    if (n > GC_PROTO_WIRE_MAX) return GC_FRAME_LENGTH;
    if (gc_cobs_decode(wire, n, body, sizeof body, &len)) {
        /* A well-formed encoding that is merely too long for any frame is a length error. */
        return GC_FRAME_COBS;
    }
    if (len < GC_PROTO_HEADER + 2) return GC_FRAME_SHORT;
    if (gc_crc16(body, len - 2) != gc_le16(body + len - 2)) return GC_FRAME_CRC;
    if (body[0] != GC_PROTO_VERSION) return GC_FRAME_VERSION;
    uint8_t type = body[1];
    if (type < GC_MSG_HELLO_HOST || type > GC_MSG_HEARTBEAT) return GC_FRAME_TYPE;
    size_t plen = len - GC_PROTO_HEADER - 2;
    if (!payload_length_ok(type, body + GC_PROTO_HEADER, plen)) return GC_FRAME_LENGTH;
    out->type = type;
    out->seq = gc_le16(body + 2);
    out->len = plen;
    memcpy(out->payload, body + GC_PROTO_HEADER, plen);
    return GC_FRAME_OK;
}

void gc_decoder_reset(gcFrameDecoder *d) { memset(d, 0, sizeof *d); }

int gc_decoder_push(gcFrameDecoder *d, uint8_t byte, gcFrame *out) {
    if (byte != 0) {
        if (d->overflow) return 0;
        if (d->len == sizeof d->buf) {
            d->overflow = 1;
            d->errors[GC_FRAME_OVERFLOW]++;
            d->len = 0;
            return 0;
        }
        d->buf[d->len++] = byte;
        return 0;
    }
    if (d->overflow) {
        d->overflow = 0;
        return 0;
    }
    if (d->len == 0) return 0;
    gcFrameError e = gc_frame_decode(d->buf, d->len, out);
    d->len = 0;
    if (e != GC_FRAME_OK) {
        d->errors[e]++;
        return 0;
    }
    d->frames++;
    return 1;
}
