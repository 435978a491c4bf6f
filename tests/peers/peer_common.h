/*
 * peer_common.h - helpers shared by the libmodbus peer fixtures
 * (libmodbus_server.c and libmodbus_client.c).
 *
 * Argument parsing for the connection flags that every fixture accepts, the
 * shared data map, and a strict number parser. Everything is `static inline`
 * so that a file which does not use a helper gets no -Wunused-function
 * warning (the fixtures are built with -Wall -Wextra -Werror).
 *
 * No ferrobus code is used here: the fixtures stand on libmodbus alone.
 */
#ifndef FERROBUS_PEER_COMMON_H
#define FERROBUS_PEER_COMMON_H

#include <errno.h>
#include <limits.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- the shared data map (see tests/peers/README.md) ------------------ */

#define MAP_REGISTERS 1000 /* holding and input registers 0..999 */
#define MAP_BITS 2000      /* coils and discrete inputs 0..1999 */

static inline uint16_t map_holding(int i) { return (uint16_t)((i * 7 + 3) & 0xFFFF); }
static inline uint16_t map_input(int i) { return (uint16_t)((0x1000 + i) & 0xFFFF); }
static inline uint8_t map_coil(int i) { return (uint8_t)(i % 3 == 0); }
static inline uint8_t map_discrete(int i) { return (uint8_t)(i % 5 == 0); }

/* ---- strict number parsing ------------------------------------------- */

/*
 * Parses a whole token as an integer in [min, max]. Accepts decimal or a
 * "0x" hexadecimal prefix (never octal: "010" is ten). Returns 0 on success,
 * -1 on any junk, overflow or range error.
 */
static inline int parse_long(const char *s, long min, long max, long *out)
{
    char *end = NULL;
    long v;
    int base = 10;

    if (s == NULL || *s == '\0')
        return -1;
    if (s[0] == '0' && (s[1] == 'x' || s[1] == 'X')) {
        base = 16;
        s += 2;
        if (*s == '\0')
            return -1;
    }
    /* strtol accepts leading blanks and a sign; we want neither for hex. */
    if (*s == ' ' || *s == '\t' || (base == 16 && (*s == '-' || *s == '+')))
        return -1;
    errno = 0;
    v = strtol(s, &end, base);
    if (errno != 0 || end == s || *end != '\0')
        return -1;
    if (v < min || v > max)
        return -1;
    *out = v;
    return 0;
}

/* ---- connection flags -------------------------------------------------- */

enum peer_transport { PEER_NONE = 0, PEER_RTU, PEER_TCP };

struct peer_conn {
    enum peer_transport transport;
    const char *path; /* --rtu PATH */
    long baud;        /* --baud B (default 19200) */
    char parity;      /* --parity N|E|O (default N) */
    long data_bits;   /* --data-bits 5..8 (default 8) */
    long stop_bits;   /* --stop-bits 1|2 (default 1) */
    const char *tcp;  /* --tcp PORT (server) or HOST:PORT (client) */
    long unit;        /* --unit U (default 1) */
    int debug;        /* --debug */
};

static inline void peer_conn_init(struct peer_conn *c)
{
    memset(c, 0, sizeof(*c));
    c->baud = 19200;
    c->parity = 'N';
    c->data_bits = 8;
    c->stop_bits = 1;
    c->unit = 1;
}

/*
 * Tries to consume one connection flag at argv[*i]. Returns 1 if the flag
 * was consumed (and advances *i past its value), 0 if argv[*i] is not a
 * connection flag, -1 on a bad value (an error was printed to stderr).
 * unit_min/unit_max bound --unit (servers: 1..247, clients: 0..255).
 */
static inline int peer_conn_parse(struct peer_conn *c, int argc, char **argv, int *i,
                                  long unit_min, long unit_max)
{
    const char *flag = argv[*i];
    const char *val;
    long v;

#define NEED_VALUE()                                                        \
    do {                                                                    \
        if (*i + 1 >= argc) {                                               \
            fprintf(stderr, "error: %s needs a value\n", flag);             \
            return -1;                                                      \
        }                                                                   \
        val = argv[++*i];                                                   \
    } while (0)

    if (strcmp(flag, "--rtu") == 0) {
        NEED_VALUE();
        if (c->transport != PEER_NONE) {
            fprintf(stderr, "error: give exactly one of --rtu or --tcp\n");
            return -1;
        }
        c->transport = PEER_RTU;
        c->path = val;
        return 1;
    }
    if (strcmp(flag, "--tcp") == 0) {
        NEED_VALUE();
        if (c->transport != PEER_NONE) {
            fprintf(stderr, "error: give exactly one of --rtu or --tcp\n");
            return -1;
        }
        c->transport = PEER_TCP;
        c->tcp = val;
        return 1;
    }
    if (strcmp(flag, "--baud") == 0) {
        NEED_VALUE();
        if (parse_long(val, 50, 4000000, &v) != 0) {
            fprintf(stderr, "error: bad --baud '%s' (50..4000000)\n", val);
            return -1;
        }
        c->baud = v;
        return 1;
    }
    if (strcmp(flag, "--parity") == 0) {
        NEED_VALUE();
        if (strcmp(val, "N") != 0 && strcmp(val, "E") != 0 && strcmp(val, "O") != 0) {
            fprintf(stderr, "error: bad --parity '%s' (N, E or O)\n", val);
            return -1;
        }
        c->parity = val[0];
        return 1;
    }
    if (strcmp(flag, "--data-bits") == 0) {
        NEED_VALUE();
        if (parse_long(val, 5, 8, &v) != 0) {
            fprintf(stderr, "error: bad --data-bits '%s' (5..8)\n", val);
            return -1;
        }
        c->data_bits = v;
        return 1;
    }
    if (strcmp(flag, "--stop-bits") == 0) {
        NEED_VALUE();
        if (parse_long(val, 1, 2, &v) != 0) {
            fprintf(stderr, "error: bad --stop-bits '%s' (1 or 2)\n", val);
            return -1;
        }
        c->stop_bits = v;
        return 1;
    }
    if (strcmp(flag, "--unit") == 0) {
        NEED_VALUE();
        if (parse_long(val, unit_min, unit_max, &v) != 0) {
            fprintf(stderr, "error: bad --unit '%s' (%ld..%ld)\n", val, unit_min, unit_max);
            return -1;
        }
        c->unit = v;
        return 1;
    }
    if (strcmp(flag, "--debug") == 0) {
        c->debug = 1;
        return 1;
    }
#undef NEED_VALUE
    return 0;
}

#endif /* FERROBUS_PEER_COMMON_H */
