/*
 * The differential-test driver for the exported evaluator (host_compiler::export::harness); not part of
 * what `export --c` writes. Reads commands from stdin, writes answers to stdout (little-endian):
 *   'I' u32 len, len bytes  init from these bytes        -> u8 sc_error
 *   'E'                     init from the exported array -> u8 sc_error
 *   'R'                     reset (and forget the applied input)
 *   'S' u8 k, k f32         one period (sc_step_plant: sc_step without model maps) with a k-value
 *                           state -> u8 status, SC_MAX_M f32: on SC_OK the input, else sc_fallback at x
 *                           with the last applied input (as the firmware), then u8 sc_location
 *   'M' i32 slack           init the task's monitor of the current image over an arena of
 *                           sc_monitor_words + slack words (at most 0 when negative; the arena filled
 *                           with a junk pattern first) -> u8 0 accepted, 1 no monitor, 2 arena too
 *                           small, 3 another refusal; then u32 sc_monitor_words
 *   'Z'                     monitor reset (nothing without a monitor initialised)
 *   'U' u8 k, k f32         one monitor update with a k-value state -> u32 lo bits, u32 hi bits, u8
 *                           verdict (0xFF and zero bits without a monitor initialised since the last
 *                           'I' or 'E')
 */
#include <stdio.h>
#include <string.h>

#include "controller.h"
#include "controller_image.h"

static uint8_t buf[1u << 22];
static uint32_t arena[SC_MAX_MONITOR_WORDS + 64u];

static int read_exact(void *p, size_t n) { return fread(p, 1, n, stdin) == n; }

static uint32_t rd32(const uint8_t *p) {
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static void put32(uint32_t v) {
    uint8_t b[4];
    b[0] = (uint8_t)v;
    b[1] = (uint8_t)(v >> 8);
    b[2] = (uint8_t)(v >> 16);
    b[3] = (uint8_t)(v >> 24);
    fwrite(b, 1, 4, stdout);
}

/* A state of k <= 16 values from stdin; 0 on a protocol error. */
static int read_state(float x[16], uint32_t *k_out) {
    uint8_t k, raw[4 * 16];
    uint32_t i, b;
    if (!read_exact(&k, 1) || k > 16 || !read_exact(raw, 4u * k)) return 0;
    for (i = 0; i < k; i++) {
        b = rd32(raw + 4 * i);
        memcpy(&x[i], &b, 4);
    }
    *k_out = k;
    return 1;
}

int main(void) {
    static sc_controller c;
    static sc_monitor mon;
    int mon_ok = 0;
    float applied[SC_MAX_M];
    int op;
    memset(applied, 0, sizeof applied);
    while ((op = getchar()) != EOF) {
        if (op == 'I' || op == 'E') {
            uint8_t e;
            if (op == 'I') {
                uint8_t l[4];
                uint32_t len;
                if (!read_exact(l, 4)) return 2;
                len = rd32(l);
                if (len > sizeof buf || !read_exact(buf, len)) return 2;
                e = (uint8_t)sc_init(&c, buf, len);
            } else {
                e = (uint8_t)sc_init(&c, sc_image_bytes, sc_image_len);
            }
            memset(applied, 0, sizeof applied);
            mon_ok = 0;
            fputc(e, stdout);
        } else if (op == 'M') {
            uint8_t l[4];
            int32_t slack;
            uint32_t words = sc_monitor_words(&c), i;
            int64_t want;
            sc_error e;
            if (!read_exact(l, 4)) return 2;
            slack = (int32_t)rd32(l);
            want = (int64_t)words + slack;
            if (want < 0) want = 0;
            if (want > (int64_t)(sizeof arena / sizeof arena[0])) return 2;
            for (i = 0; i < sizeof arena / sizeof arena[0]; i++) arena[i] = 0xDEADBEEFu;
            e = sc_monitor_init(&mon, &c, arena, (uint32_t)want);
            mon_ok = e == SC_E_NONE;
            fputc(e == SC_E_NONE ? 0 : e == SC_E_NO_MONITOR ? 1 : e == SC_E_MONITOR_ARENA ? 2 : 3,
                  stdout);
            put32(words);
        } else if (op == 'Z') {
            if (mon_ok) sc_monitor_reset(&mon);
        } else if (op == 'U') {
            float x[16];
            uint32_t k, b;
            sc_monitor_report r;
            if (!read_state(x, &k)) return 2;
            if (mon_ok) {
                sc_monitor_update(&mon, x, k, &r);
                memcpy(&b, &r.lo, 4);
                put32(b);
                memcpy(&b, &r.hi, 4);
                put32(b);
                fputc(r.verdict, stdout);
            } else {
                put32(0);
                put32(0);
                fputc(0xFF, stdout);
            }
        } else if (op == 'R') {
            sc_reset(&c);
            memset(applied, 0, sizeof applied);
        } else if (op == 'S') {
            float x[16], u[SC_MAX_M];
            uint32_t i, b, k;
            sc_status s;
            if (!read_state(x, &k)) return 2;
            memset(u, 0, sizeof u);
            s = sc_step_plant(&c, x, k, u);
            if (s != SC_OK) sc_fallback(&c, x, k, applied, u);
            memcpy(applied, u, sizeof u);
            fputc((int)s, stdout);
            for (i = 0; i < SC_MAX_M; i++) {
                memcpy(&b, &u[i], 4);
                put32(b);
            }
            fputc((int)sc_location(&c), stdout);
        } else {
            return 2;
        }
    }
    fflush(stdout);
    return 0;
}
