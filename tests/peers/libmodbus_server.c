/*
 * libmodbus_server - a Modbus server fixture built on libmodbus (3.1.x).
 *
 * Serves the shared data map (tests/peers/README.md) for one unit id, over
 * RTU on a tty (e.g. one end of a socat pty pair) or over TCP on 127.0.0.1.
 *
 *   libmodbus_server --rtu PATH [--baud B] [--parity N|E|O] [--data-bits 8]
 *                    [--stop-bits 1|2] [--unit U] [--response-timeout-ms N]
 *                    [--service-us N] [--debug]
 *   libmodbus_server --tcp PORT [--unit U] [--response-timeout-ms N] [--service-us N] [--debug]
 *
 * Contract:
 *   - stdout carries exactly one line, "READY", written and flushed once
 *     requests can be accepted. Anything else (libmodbus --debug traces,
 *     notes, errors) goes to stderr: stdout is pointed at stderr right after
 *     startup, so libmodbus's debug printf()s cannot pollute it.
 *   - SIGTERM / SIGINT end the process with exit status 0.
 *   - Bad arguments: usage on stderr, exit 2. Cannot open the port or bind
 *     the socket: message on stderr, exit 1.
 *   - Only unit U is answered. On RTU libmodbus filters other units itself
 *     (modbus_set_slave); broadcast (unit 0) writes are executed but never
 *     answered. libmodbus does NOT filter on TCP, so this program drops TCP
 *     requests whose MBAP unit id is not U (including 0 and 255) without a
 *     reply, to keep the same contract on both transports.
 *   - libmodbus quirks kept as they are (see README.md): on RTU, after a
 *     request for another unit the server treats the next frame that starts
 *     within the response timeout as that unit's reply and discards it; a
 *     request with an illegal quantity (and, on TCP, an unknown function
 *     code) is answered with exception 03 (01) only after sleeping for the
 *     response timeout. --response-timeout-ms sets that timeout (libmodbus
 *     default 500).
 *   - Bad frames (CRC errors, truncated or unparsable frames) are skipped:
 *     RTU keeps reading, TCP closes that connection and accepts the next one.
 *     TCP connections are served one after another, never in parallel, so an
 *     idle connected client holds the server until it disconnects.
 *   - --service-us N models a device that takes time per request: the server
 *     sleeps N microseconds (default 0: not at all) after it has received a
 *     request it is going to execute (unit U; on RTU also a broadcast) and
 *     before it executes and answers it.
 */
#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include <modbus.h>

#include "peer_common.h"

static void usage(FILE *out)
{
    fprintf(out,
            "usage: libmodbus_server --rtu PATH [--baud B] [--parity N|E|O] [--data-bits 5..8]\n"
            "                        [--stop-bits 1|2] [--unit U] [--response-timeout-ms N]\n"
            "                        [--service-us N] [--debug]\n"
            "       libmodbus_server --tcp PORT [--unit U] [--response-timeout-ms N] [--service-us N]\n"
            "                        [--debug]\n"
            "\n"
            "Serves the ferrobus peer data map for unit U (default 1, range 1..247).\n"
            "Prints READY on stdout when serving; exits 0 on SIGTERM/SIGINT.\n"
            "--tcp binds 127.0.0.1:PORT and serves one connection after another.\n"
            "--response-timeout-ms sets libmodbus's response timeout (default 500), which the\n"
            "server uses to skip another unit's reply and to delay exceptions 03 and 01.\n"
            "--service-us N sleeps N microseconds (0..10000000, default 0) before each request it\n"
            "executes and answers: a device that takes time per request.\n");
}

/*
 * libmodbus restarts select() itself when a signal interrupts it (it prints
 * "A non blocked signal was caught" and loops), so a flag set by a handler
 * would never be seen while modbus_receive() waits. _exit() is
 * async-signal-safe and the kernel closes the port / sockets for us.
 */
static void on_signal(int sig)
{
    (void)sig;
    _exit(0);
}

static void install_signals(void)
{
    struct sigaction sa;

    memset(&sa, 0, sizeof(sa));
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, &sa, NULL);
    signal(SIGPIPE, SIG_IGN); /* a client that vanishes must not kill us */
}

static modbus_mapping_t *new_data_map(void)
{
    modbus_mapping_t *map =
        modbus_mapping_new_start_address(0, MAP_BITS, 0, MAP_BITS, 0, MAP_REGISTERS, 0, MAP_REGISTERS);
    int i;

    if (map == NULL)
        return NULL;
    for (i = 0; i < MAP_BITS; i++) {
        map->tab_bits[i] = map_coil(i);
        map->tab_input_bits[i] = map_discrete(i);
    }
    for (i = 0; i < MAP_REGISTERS; i++) {
        map->tab_registers[i] = map_holding(i);
        map->tab_input_registers[i] = map_input(i);
    }
    return map;
}

/*
 * Keeps the real stdout for the READY line only and sends every other write
 * to stdout (libmodbus debug output) to stderr. Returns the fd of the real
 * stdout, or -1.
 */
static int split_stdout(void)
{
    int ready_fd = dup(STDOUT_FILENO);

    if (ready_fd < 0)
        return -1;
    if (dup2(STDERR_FILENO, STDOUT_FILENO) < 0) {
        close(ready_fd);
        return -1;
    }
    setvbuf(stdout, NULL, _IOLBF, 0);
    return ready_fd;
}

static void say_ready(int ready_fd)
{
    static const char line[] = "READY\n";
    ssize_t n;

    do {
        n = write(ready_fd, line, sizeof(line) - 1);
    } while (n < 0 && errno == EINTR);
    /* ready_fd stays open: closing it would look like an early EOF. */
}

/* Sleeps us microseconds (none for 0), to the end even when a signal interrupts it. */
static void service_wait(long us)
{
    struct timespec left;

    if (us <= 0)
        return;
    left.tv_sec = us / 1000000;
    left.tv_nsec = (us % 1000000) * 1000;
    while (nanosleep(&left, &left) != 0 && errno == EINTR) {
    }
}

/* True for errors that say "this frame was bad" rather than "the port is gone". */
static int is_frame_error(int err)
{
    return err == EMBBADCRC || err == EMBBADDATA || err == EMBBADEXC || err == EMBUNKEXC ||
           err == EMBMDATA || err == EMBBADSLAVE || err == ETIMEDOUT || err == ENOPROTOOPT ||
           (err > MODBUS_ENOBASE && err <= EMBXGTAR);
}

static int serve_rtu(const struct peer_conn *c, long resp_ms, long service_us, modbus_mapping_t *map,
                     int ready_fd)
{
    uint8_t query[MODBUS_RTU_MAX_ADU_LENGTH];
    modbus_t *ctx = modbus_new_rtu(c->path, (int)c->baud, c->parity, (int)c->data_bits, (int)c->stop_bits);
    int io_errors = 0;
    int is_open = 1;

    if (ctx == NULL) {
        fprintf(stderr, "libmodbus_server: modbus_new_rtu: %s\n", modbus_strerror(errno));
        return 1;
    }
    modbus_set_debug(ctx, c->debug);
    if (resp_ms >= 0)
        modbus_set_response_timeout(ctx, (uint32_t)(resp_ms / 1000), (uint32_t)((resp_ms % 1000) * 1000));
    if (modbus_set_slave(ctx, (int)c->unit) != 0 || modbus_connect(ctx) != 0) {
        fprintf(stderr, "libmodbus_server: cannot open %s: %s\n", c->path, modbus_strerror(errno));
        modbus_free(ctx);
        return 1;
    }
    say_ready(ready_fd);

    for (;;) {
        int rc;

        if (!is_open) {
            /* Never hand a closed context to modbus_receive(): its select() would abort on fd -1. */
            sleep(1);
            if (modbus_connect(ctx) == 0) {
                is_open = 1;
                io_errors = 0;
                fprintf(stderr, "libmodbus_server: reopened %s\n", c->path);
            }
            continue;
        }
        rc = modbus_receive(ctx, query);
        if (rc > 0) {
            io_errors = 0;
            service_wait(service_us);
            /*
             * modbus_reply() also executes broadcast writes and then stays
             * silent. It returns -1 for function codes it refuses to answer
             * (FC 07 gives ENOPROTOOPT): nothing is sent then, which is what
             * a real device on a shared line would do too.
             */
            if (modbus_reply(ctx, query, rc, map) < 0 && !is_frame_error(errno) && c->debug)
                fprintf(stderr, "libmodbus_server: reply failed: %s\n", modbus_strerror(errno));
            continue;
        }
        if (rc == 0)
            continue; /* a request for another unit (or its reply): ignored by libmodbus */
        if (is_frame_error(errno)) {
            if (c->debug)
                fprintf(stderr, "libmodbus_server: dropped frame: %s\n", modbus_strerror(errno));
            continue;
        }
        /*
         * The port itself failed (e.g. EIO or ECONNRESET when the other end of
         * a pty pair went away). Do not spin: back off, and after a few
         * failures in a row close the port and try to reopen it once a second.
         */
        if (io_errors++ == 0)
            fprintf(stderr, "libmodbus_server: port error: %s; retrying\n", modbus_strerror(errno));
        usleep(50000);
        if (io_errors >= 10) {
            modbus_close(ctx);
            is_open = 0;
        }
    }
}

static int serve_tcp(const struct peer_conn *c, long port, long resp_ms, long service_us, modbus_mapping_t *map,
                     int ready_fd)
{
    uint8_t query[MODBUS_TCP_MAX_ADU_LENGTH];
    modbus_t *ctx;
    int listen_s;
    int unit_pos;

    ctx = modbus_new_tcp("127.0.0.1", (int)port);
    if (ctx == NULL) {
        fprintf(stderr, "libmodbus_server: modbus_new_tcp: %s\n", modbus_strerror(errno));
        return 1;
    }
    modbus_set_debug(ctx, c->debug);
    if (resp_ms >= 0)
        modbus_set_response_timeout(ctx, (uint32_t)(resp_ms / 1000), (uint32_t)((resp_ms % 1000) * 1000));
    modbus_set_slave(ctx, (int)c->unit);
    listen_s = modbus_tcp_listen(ctx, 16);
    if (listen_s < 0) {
        fprintf(stderr, "libmodbus_server: cannot listen on 127.0.0.1:%ld: %s\n", port,
                modbus_strerror(errno));
        modbus_free(ctx);
        return 1;
    }
    unit_pos = modbus_get_header_length(ctx) - 1; /* MBAP byte 6 */
    say_ready(ready_fd);

    for (;;) {
        if (modbus_tcp_accept(ctx, &listen_s) < 0) {
            if (errno != EINTR && errno != ECONNABORTED)
                fprintf(stderr, "libmodbus_server: accept: %s\n", modbus_strerror(errno));
            usleep(10000);
            continue;
        }
        for (;;) {
            int rc = modbus_receive(ctx, query);

            if (rc > 0) {
                if (query[unit_pos] != (uint8_t)c->unit) {
                    if (c->debug)
                        fprintf(stderr, "libmodbus_server: ignoring unit %u\n", query[unit_pos]);
                    continue;
                }
                service_wait(service_us);
                if (modbus_reply(ctx, query, rc, map) < 0 && !is_frame_error(errno))
                    break; /* the send failed: the connection is gone */
                continue;
            }
            if (rc == 0)
                continue;
            /*
             * A closed connection (ECONNRESET) or any framing error: libmodbus
             * reads TCP by function-code length, not by the MBAP length, so
             * after a bad frame the stream position is unknown. Start over.
             */
            if (c->debug)
                fprintf(stderr, "libmodbus_server: closing connection: %s\n", modbus_strerror(errno));
            break;
        }
        modbus_close(ctx);
    }
}

int main(int argc, char **argv)
{
    struct peer_conn c;
    modbus_mapping_t *map;
    long port = 0;
    long resp_ms = -1; /* -1: keep libmodbus's default */
    long service_us = 0;
    int ready_fd;
    int i;

    peer_conn_init(&c);
    for (i = 1; i < argc; i++) {
        int r;

        if (strcmp(argv[i], "--help") == 0 || strcmp(argv[i], "-h") == 0) {
            usage(stdout);
            return 0;
        }
        if (strcmp(argv[i], "--response-timeout-ms") == 0) {
            if (i + 1 >= argc || parse_long(argv[i + 1], 0, 60000, &resp_ms) != 0) {
                fprintf(stderr, "error: --response-timeout-ms needs a number in 0..60000\n");
                usage(stderr);
                return 2;
            }
            i++;
            continue;
        }
        if (strcmp(argv[i], "--service-us") == 0) {
            if (i + 1 >= argc || parse_long(argv[i + 1], 0, 10000000, &service_us) != 0) {
                fprintf(stderr, "error: --service-us needs a number in 0..10000000\n");
                usage(stderr);
                return 2;
            }
            i++;
            continue;
        }
        r = peer_conn_parse(&c, argc, argv, &i, 1, 247);
        if (r < 0) {
            usage(stderr);
            return 2;
        }
        if (r == 0) {
            fprintf(stderr, "error: unknown argument '%s'\n", argv[i]);
            usage(stderr);
            return 2;
        }
    }
    if (c.transport == PEER_NONE) {
        fprintf(stderr, "error: give --rtu PATH or --tcp PORT\n");
        usage(stderr);
        return 2;
    }
    if (c.transport == PEER_TCP && parse_long(c.tcp, 1, 65535, &port) != 0) {
        fprintf(stderr, "error: bad --tcp '%s' (a port 1..65535)\n", c.tcp);
        usage(stderr);
        return 2;
    }

    install_signals();
    map = new_data_map();
    if (map == NULL) {
        fprintf(stderr, "libmodbus_server: cannot allocate the data map: %s\n", modbus_strerror(errno));
        return 1;
    }
    ready_fd = split_stdout();
    if (ready_fd < 0) {
        fprintf(stderr, "libmodbus_server: cannot set up stdout: %s\n", strerror(errno));
        return 1;
    }
    if (c.transport == PEER_RTU)
        return serve_rtu(&c, resp_ms, service_us, map, ready_fd);
    return serve_tcp(&c, port, resp_ms, service_us, map, ready_fd);
}
