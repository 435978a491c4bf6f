/*
 * libmodbus_client - a Modbus client fixture built on libmodbus (3.1.x).
 *
 *   libmodbus_client CONN [--unit U] [--timeout-ms N] [--debug] script
 *   libmodbus_client CONN [--unit U] [--timeout-ms N] [--debug] bench --count N
 *                    [--address A] [--quantity Q]
 *
 *   CONN is --rtu PATH [--baud B] [--parity N|E|O] [--data-bits 8] [--stop-bits 1|2]
 *        or --tcp HOST:PORT
 *
 * script: reads one command per line on stdin and prints exactly one result
 * line per command on stdout (blank lines and lines starting with '#' are
 * skipped without output). The line format is the contract documented in
 * tests/peers/README.md ("ok ...", "exception N", "timeout", "error TEXT").
 *
 * bench: performs N FC03 reads back to back and prints one JSON object.
 *
 * Exit status: 0 when stdin is exhausted (whatever the individual commands
 * answered) or the bench finished; 1 when the port/connection cannot be
 * opened at startup; 2 for bad arguments (usage on stderr).
 */
#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include <modbus.h>

#include "peer_common.h"

#define MAX_LINE (1 << 20) /* longer script lines are rejected */
#define MAX_TOKENS 4096

/*
 * Result lines go to g_out, a copy of the original stdout. The process's
 * stdout itself is pointed at stderr, because libmodbus --debug traces are
 * printf()s and must not interleave with the result lines.
 */
static FILE *g_out;

static void usage(FILE *out)
{
    fprintf(out,
            "usage: libmodbus_client CONN [--unit U] [--timeout-ms N] [--debug] script\n"
            "       libmodbus_client CONN [--unit U] [--timeout-ms N] [--debug] bench --count N\n"
            "                        [--address A] [--quantity Q]\n"
            "CONN:  --rtu PATH [--baud B] [--parity N|E|O] [--data-bits 5..8] [--stop-bits 1|2]\n"
            "       --tcp HOST:PORT\n"
            "Defaults: --unit 1, --timeout-ms 1000, --address 0, --quantity 10.\n"
            "script reads commands from stdin; see tests/peers/README.md for the line format.\n");
}

/* ---- connection -------------------------------------------------------- */

struct client {
    modbus_t *ctx;
    int connected;
    int header_length; /* 1 on RTU, 7 on TCP */
};

static int is_connection_error(int err)
{
    return err == ECONNRESET || err == EPIPE || err == EBADF || err == ENOTCONN ||
           err == ECONNREFUSED || err == EIO;
}

/* Builds the libmodbus context; returns NULL (message printed) on failure. */
static modbus_t *new_context(const struct peer_conn *c)
{
    modbus_t *ctx = NULL;

    if (c->transport == PEER_RTU) {
        ctx = modbus_new_rtu(c->path, (int)c->baud, c->parity, (int)c->data_bits, (int)c->stop_bits);
    } else {
        /* HOST:PORT; the last ':' splits, so "[::1]:502" works too. */
        char host[256];
        const char *colon = strrchr(c->tcp, ':');
        size_t hlen;
        long port;

        if (colon == NULL || parse_long(colon + 1, 1, 65535, &port) != 0) {
            fprintf(stderr, "error: bad --tcp '%s' (HOST:PORT)\n", c->tcp);
            return NULL;
        }
        hlen = (size_t)(colon - c->tcp);
        if (hlen >= 2 && c->tcp[0] == '[' && c->tcp[hlen - 1] == ']') {
            memcpy(host, c->tcp + 1, hlen - 2);
            host[hlen - 2] = '\0';
        } else if (hlen > 0 && hlen < sizeof(host)) {
            memcpy(host, c->tcp, hlen);
            host[hlen] = '\0';
        } else {
            fprintf(stderr, "error: bad --tcp '%s' (HOST:PORT)\n", c->tcp);
            return NULL;
        }
        /* The _pi variant resolves names ("localhost") and IPv6. */
        ctx = modbus_new_tcp_pi(host, colon + 1);
    }
    if (ctx == NULL)
        fprintf(stderr, "libmodbus_client: cannot create context: %s\n", modbus_strerror(errno));
    return ctx;
}

/* Reconnects lazily after a connection error; returns 0 when usable. */
static int ensure_connected(struct client *cl)
{
    if (cl->connected)
        return 0;
    modbus_close(cl->ctx);
    if (modbus_connect(cl->ctx) != 0)
        return -1;
    cl->connected = 1;
    return 0;
}

/* ---- result lines ------------------------------------------------------ */

static void print_failure(struct client *cl, int err)
{
    if (err > MODBUS_ENOBASE && err <= EMBXGTAR) {
        fprintf(g_out, "exception %d\n", err - MODBUS_ENOBASE);
        return;
    }
    if (err == ETIMEDOUT) {
        fprintf(g_out, "timeout\n");
        /* Drop whatever a late or partial answer left behind. */
        modbus_flush(cl->ctx);
        return;
    }
    fprintf(g_out, "error %s\n", modbus_strerror(err));
    if (is_connection_error(err))
        cl->connected = 0;
    else
        modbus_flush(cl->ctx);
}

static void print_registers(const uint16_t *v, int n)
{
    int i;

    fprintf(g_out, "ok");
    for (i = 0; i < n; i++)
        fprintf(g_out, " %u", v[i]);
    fprintf(g_out, "\n");
}

static void print_bits(const uint8_t *v, int n)
{
    int i;

    fprintf(g_out, "ok");
    for (i = 0; i < n; i++)
        fprintf(g_out, " %u", v[i] ? 1u : 0u);
    fprintf(g_out, "\n");
}

/* ---- script commands --------------------------------------------------- */

static uint16_t g_regs[65536];
static uint16_t g_regs2[65536];
static uint8_t g_bits[65536];

static int arg_u16(const char *s, long *out) { return parse_long(s, 0, 65535, out); }

/*
 * Parses tok[first..n-1] as 16-bit values (registers) or 0/1 (coils) into
 * the given array. Returns the count or -1.
 */
static int parse_values(char **tok, int first, int n, int bits, uint16_t *regs, uint8_t *bitv)
{
    int i;

    for (i = first; i < n; i++) {
        long v;

        if (parse_long(tok[i], 0, bits ? 1 : 65535, &v) != 0)
            return -1;
        if (bits)
            bitv[i - first] = (uint8_t)v;
        else
            regs[i - first] = (uint16_t)v;
    }
    return n - first;
}

/*
 * FC 07 is not in libmodbus's client API, but its response has a fixed
 * length that libmodbus's receive path understands, so it is sent raw.
 */
static void cmd_read_exception_status(struct client *cl)
{
    uint8_t req[2];
    uint8_t rsp[MODBUS_TCP_MAX_ADU_LENGTH];
    int rc;

    req[0] = (uint8_t)modbus_get_slave(cl->ctx);
    req[1] = 0x07;
    if (modbus_send_raw_request(cl->ctx, req, 2) < 0) {
        print_failure(cl, errno);
        return;
    }
    rc = modbus_receive_confirmation(cl->ctx, rsp);
    if (rc < 0) {
        print_failure(cl, errno);
        return;
    }
    if (rc < cl->header_length + 2) {
        fprintf(g_out, "error short response\n");
        return;
    }
    if (rsp[cl->header_length] == 0x87) {
        fprintf(g_out, "exception %u\n", rsp[cl->header_length + 1]);
        return;
    }
    if (rsp[cl->header_length] != 0x07) {
        fprintf(g_out, "error unexpected function code 0x%02x\n", rsp[cl->header_length]);
        return;
    }
    fprintf(g_out, "ok %u\n", rsp[cl->header_length + 1]);
}

#define USAGE_ERR(text)                                                     \
    do {                                                                    \
        fprintf(g_out, "error usage: %s\n", text);                                  \
        return;                                                             \
    } while (0)

static void run_command(struct client *cl, char **tok, int n)
{
    const char *cmd = tok[0];
    long a, b, c2;
    int rc;

    /* Commands that do not touch the bus. */
    if (strcmp(cmd, "unit") == 0) {
        if (n != 2 || parse_long(tok[1], 0, 255, &a) != 0)
            USAGE_ERR("unit U");
        modbus_set_slave(cl->ctx, (int)a);
        fprintf(g_out, "ok\n");
        return;
    }
    if (strcmp(cmd, "sleep") == 0) {
        if (n != 2 || parse_long(tok[1], 0, 60000, &a) != 0)
            USAGE_ERR("sleep MS");
        usleep((useconds_t)a * 1000u);
        fprintf(g_out, "ok\n");
        return;
    }
    if (strcmp(cmd, "diag") == 0 || strcmp(cmd, "read_device_id") == 0 || strcmp(cmd, "read_fifo") == 0 ||
        strcmp(cmd, "read_file") == 0 || strcmp(cmd, "write_file") == 0) {
        fprintf(g_out, "error unsupported by libmodbus client: %s\n", cmd);
        return;
    }

    if (ensure_connected(cl) != 0) {
        fprintf(g_out, "error connect: %s\n", modbus_strerror(errno));
        return;
    }

    if (strcmp(cmd, "read_holding") == 0 || strcmp(cmd, "read_input") == 0) {
        if (n != 3 || arg_u16(tok[1], &a) != 0 || arg_u16(tok[2], &b) != 0)
            USAGE_ERR("read_holding|read_input ADDR COUNT");
        rc = cmd[5] == 'h' ? modbus_read_registers(cl->ctx, (int)a, (int)b, g_regs)
                           : modbus_read_input_registers(cl->ctx, (int)a, (int)b, g_regs);
        if (rc < 0)
            print_failure(cl, errno);
        else
            print_registers(g_regs, rc);
    } else if (strcmp(cmd, "read_coils") == 0 || strcmp(cmd, "read_discrete") == 0) {
        if (n != 3 || arg_u16(tok[1], &a) != 0 || arg_u16(tok[2], &b) != 0)
            USAGE_ERR("read_coils|read_discrete ADDR COUNT");
        rc = cmd[5] == 'c' ? modbus_read_bits(cl->ctx, (int)a, (int)b, g_bits)
                           : modbus_read_input_bits(cl->ctx, (int)a, (int)b, g_bits);
        if (rc < 0)
            print_failure(cl, errno);
        else
            print_bits(g_bits, rc);
    } else if (strcmp(cmd, "write_coil") == 0) {
        if (n != 3 || arg_u16(tok[1], &a) != 0 || parse_long(tok[2], 0, 1, &b) != 0)
            USAGE_ERR("write_coil ADDR 0|1");
        if (modbus_write_bit(cl->ctx, (int)a, (int)b) < 0)
            print_failure(cl, errno);
        else
            fprintf(g_out, "ok\n");
    } else if (strcmp(cmd, "write_register") == 0) {
        if (n != 3 || arg_u16(tok[1], &a) != 0 || arg_u16(tok[2], &b) != 0)
            USAGE_ERR("write_register ADDR VALUE");
        if (modbus_write_register(cl->ctx, (int)a, (uint16_t)b) < 0)
            print_failure(cl, errno);
        else
            fprintf(g_out, "ok\n");
    } else if (strcmp(cmd, "write_coils") == 0) {
        int cnt;

        if (n < 3 || arg_u16(tok[1], &a) != 0 || (cnt = parse_values(tok, 2, n, 1, NULL, g_bits)) < 0)
            USAGE_ERR("write_coils ADDR 0|1 [0|1 ...]");
        if (modbus_write_bits(cl->ctx, (int)a, cnt, g_bits) < 0)
            print_failure(cl, errno);
        else
            fprintf(g_out, "ok\n");
    } else if (strcmp(cmd, "write_registers") == 0) {
        int cnt;

        if (n < 3 || arg_u16(tok[1], &a) != 0 || (cnt = parse_values(tok, 2, n, 0, g_regs, NULL)) < 0)
            USAGE_ERR("write_registers ADDR VALUE [VALUE ...]");
        if (modbus_write_registers(cl->ctx, (int)a, cnt, g_regs) < 0)
            print_failure(cl, errno);
        else
            fprintf(g_out, "ok\n");
    } else if (strcmp(cmd, "mask_write") == 0) {
        if (n != 4 || arg_u16(tok[1], &a) != 0 || arg_u16(tok[2], &b) != 0 || arg_u16(tok[3], &c2) != 0)
            USAGE_ERR("mask_write ADDR AND OR");
        if (modbus_mask_write_register(cl->ctx, (int)a, (uint16_t)b, (uint16_t)c2) < 0)
            print_failure(cl, errno);
        else
            fprintf(g_out, "ok\n");
    } else if (strcmp(cmd, "write_read") == 0) {
        int cnt;

        if (n < 5 || arg_u16(tok[1], &a) != 0 || arg_u16(tok[2], &b) != 0 || arg_u16(tok[3], &c2) != 0 ||
            (cnt = parse_values(tok, 4, n, 0, g_regs2, NULL)) < 0)
            USAGE_ERR("write_read READ_ADDR READ_COUNT WRITE_ADDR VALUE [VALUE ...]");
        rc = modbus_write_and_read_registers(cl->ctx, (int)c2, cnt, g_regs2, (int)a, (int)b, g_regs);
        if (rc < 0)
            print_failure(cl, errno);
        else
            print_registers(g_regs, rc);
    } else if (strcmp(cmd, "report_slave_id") == 0) {
        uint8_t id[MODBUS_MAX_PDU_LENGTH];
        int i;

        if (n != 1)
            USAGE_ERR("report_slave_id");
        /* Returns the byte count; dest gets the bytes after the count. */
        rc = modbus_report_slave_id(cl->ctx, (int)sizeof(id), id);
        if (rc < 0) {
            print_failure(cl, errno);
            return;
        }
        fprintf(g_out, "ok");
        for (i = 0; i < rc && i < (int)sizeof(id); i++)
            fprintf(g_out, " %02x", id[i]);
        fprintf(g_out, "\n");
    } else if (strcmp(cmd, "read_exception_status") == 0) {
        if (n != 1)
            USAGE_ERR("read_exception_status");
        cmd_read_exception_status(cl);
    } else {
        fprintf(g_out, "error unknown command: %s\n", cmd);
    }
}

static int run_script(struct client *cl)
{
    char *line = NULL;
    size_t cap = 0;
    ssize_t len;
    static char *tok[MAX_TOKENS];

    while ((len = getline(&line, &cap, stdin)) >= 0) {
        int n = 0;
        char *save = NULL;
        char *t;

        if (len > MAX_LINE) {
            fprintf(g_out, "error line too long\n");
            fflush(g_out);
            continue;
        }
        for (t = strtok_r(line, " \t\r\n", &save); t != NULL; t = strtok_r(NULL, " \t\r\n", &save)) {
            if (n == MAX_TOKENS) {
                n = -1;
                break;
            }
            tok[n++] = t;
        }
        if (n == 0 || (n > 0 && tok[0][0] == '#'))
            continue;
        if (n < 0)
            fprintf(g_out, "error too many values\n");
        else
            run_command(cl, tok, n);
        fflush(g_out);
    }
    free(line);
    return 0;
}

/* ---- bench ------------------------------------------------------------- */

static int cmp_u64(const void *x, const void *y)
{
    uint64_t a = *(const uint64_t *)x, b = *(const uint64_t *)y;

    return (a > b) - (a < b);
}

/* Nearest-rank percentile of a sorted array, in microseconds. */
static double percentile_us(const uint64_t *sorted, long n, int p)
{
    long rank = (long)(((double)p / 100.0) * (double)n + 0.999999);

    if (rank < 1)
        rank = 1;
    if (rank > n)
        rank = n;
    return (double)sorted[rank - 1] / 1000.0;
}

static double tv_seconds(struct timeval tv) { return (double)tv.tv_sec + (double)tv.tv_usec / 1e6; }

static uint64_t ns_between(const struct timespec *a, const struct timespec *b)
{
    return (uint64_t)((b->tv_sec - a->tv_sec) * 1000000000LL + (b->tv_nsec - a->tv_nsec));
}

static int run_bench(struct client *cl, long count, long address, long quantity)
{
    uint64_t *lat = malloc((size_t)count * sizeof(*lat));
    struct timespec start, end, t0, t1;
    struct rusage ru;
    long errors = 0;
    long i;
    double seconds;

    if (lat == NULL) {
        fprintf(stderr, "libmodbus_client: cannot allocate %ld latencies\n", count);
        return 1;
    }
    clock_gettime(CLOCK_MONOTONIC, &start);
    for (i = 0; i < count; i++) {
        int rc;

        clock_gettime(CLOCK_MONOTONIC, &t0);
        if (ensure_connected(cl) != 0)
            rc = -1;
        else
            rc = modbus_read_registers(cl->ctx, (int)address, (int)quantity, g_regs);
        clock_gettime(CLOCK_MONOTONIC, &t1);
        lat[i] = ns_between(&t0, &t1);
        if (rc != quantity) {
            int err = errno;

            errors++;
            if (rc < 0 && is_connection_error(err))
                cl->connected = 0;
            else if (rc < 0 && !(err > MODBUS_ENOBASE && err <= EMBXGTAR))
                modbus_flush(cl->ctx);
        }
    }
    clock_gettime(CLOCK_MONOTONIC, &end);
    getrusage(RUSAGE_SELF, &ru);
    seconds = (double)ns_between(&start, &end) / 1e9;
    qsort(lat, (size_t)count, sizeof(*lat), cmp_u64);
    fprintf(g_out, "{\"transactions\":%ld,\"errors\":%ld,\"seconds\":%.6f,\"tps\":%.1f,\"p50_us\":%.1f,"
           "\"p99_us\":%.1f,\"user_s\":%.6f,\"sys_s\":%.6f}\n",
           count, errors, seconds, seconds > 0 ? (double)count / seconds : 0.0, percentile_us(lat, count, 50),
           percentile_us(lat, count, 99), tv_seconds(ru.ru_utime), tv_seconds(ru.ru_stime));
    fflush(g_out);
    free(lat);
    return 0;
}

/* ---- main -------------------------------------------------------------- */

int main(int argc, char **argv)
{
    struct peer_conn c;
    struct client cl;
    const char *mode = NULL;
    long timeout_ms = 1000, count = -1, address = 0, quantity = 10;
    int i, rc;

    peer_conn_init(&c);
    for (i = 1; i < argc; i++) {
        const char *f = argv[i];
        long *target = NULL;
        long lo = 0, hi = 0;
        int r;

        if (strcmp(f, "--help") == 0 || strcmp(f, "-h") == 0) {
            usage(stdout);
            return 0;
        }
        r = peer_conn_parse(&c, argc, argv, &i, 0, 255);
        if (r < 0) {
            usage(stderr);
            return 2;
        }
        if (r > 0)
            continue;
        if (strcmp(f, "script") == 0 || strcmp(f, "bench") == 0) {
            if (mode != NULL) {
                fprintf(stderr, "error: give one mode (script or bench)\n");
                usage(stderr);
                return 2;
            }
            mode = f;
            continue;
        }
        if (strcmp(f, "--timeout-ms") == 0) {
            target = &timeout_ms, lo = 1, hi = 600000;
        } else if (strcmp(f, "--count") == 0) {
            target = &count, lo = 1, hi = 100000000;
        } else if (strcmp(f, "--address") == 0) {
            target = &address, lo = 0, hi = 65535;
        } else if (strcmp(f, "--quantity") == 0) {
            target = &quantity, lo = 1, hi = MODBUS_MAX_READ_REGISTERS;
        } else {
            fprintf(stderr, "error: unknown argument '%s'\n", f);
            usage(stderr);
            return 2;
        }
        if (i + 1 >= argc || parse_long(argv[i + 1], lo, hi, target) != 0) {
            fprintf(stderr, "error: %s needs a number in %ld..%ld\n", f, lo, hi);
            usage(stderr);
            return 2;
        }
        i++;
    }
    if (c.transport == PEER_NONE || mode == NULL) {
        fprintf(stderr, "error: give --rtu PATH or --tcp HOST:PORT, and a mode (script or bench)\n");
        usage(stderr);
        return 2;
    }
    if (strcmp(mode, "bench") == 0 && count < 0) {
        fprintf(stderr, "error: bench needs --count N\n");
        usage(stderr);
        return 2;
    }
    if (strcmp(mode, "script") == 0 && count >= 0) {
        fprintf(stderr, "error: --count is for bench mode\n");
        usage(stderr);
        return 2;
    }

    signal(SIGPIPE, SIG_IGN);
    {
        int fd = dup(STDOUT_FILENO);

        if (fd < 0 || (g_out = fdopen(fd, "w")) == NULL || dup2(STDERR_FILENO, STDOUT_FILENO) < 0) {
            fprintf(stderr, "libmodbus_client: cannot set up stdout: %s\n", strerror(errno));
            return 1;
        }
    }
    cl.ctx = new_context(&c);
    if (cl.ctx == NULL)
        return c.transport == PEER_TCP ? 2 : 1;
    modbus_set_debug(cl.ctx, c.debug);
    modbus_set_slave(cl.ctx, (int)c.unit);
    modbus_set_response_timeout(cl.ctx, (uint32_t)(timeout_ms / 1000), (uint32_t)((timeout_ms % 1000) * 1000));
    cl.header_length = modbus_get_header_length(cl.ctx);
    if (modbus_connect(cl.ctx) != 0) {
        fprintf(stderr, "libmodbus_client: cannot connect to %s: %s\n",
                c.transport == PEER_RTU ? c.path : c.tcp, modbus_strerror(errno));
        modbus_free(cl.ctx);
        return 1;
    }
    cl.connected = 1;

    if (strcmp(mode, "script") == 0)
        rc = run_script(&cl);
    else
        rc = run_bench(&cl, count, address, quantity);
    modbus_close(cl.ctx);
    modbus_free(cl.ctx);
    return rc;
}
