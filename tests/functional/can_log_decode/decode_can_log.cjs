// Test: a run's CAN log (candump -L), decoded with deploy/edgetrack.dbc by candied, gives its poses.
//
// Usage: node decode_can_log.cjs --edgetrack PROGRAM --dbc FILE --work DIR [--emulator CMD...]
//
// Runs `edgetrack run --board sim` with the two cubes' true layouts as models, receives its DTrack
// datagrams on a loopback UDP socket and logs its classic CAN frames with --can-log; then decodes
// every logged frame through the DBC with candied (an npm DBC library that shares no code with
// edgetrack) and checks that each pose on CAN is the DTrack pose of the same frame and body within
// the signals' resolution. Exit 0: pass, 1: fail, 77: skipped (candied not installed).
'use strict';

const childProcess = require('node:child_process');
const dgram = require('node:dgram');
const fs = require('node:fs');
const path = require('node:path');

let candied;
try {
    candied = require('candied');
} catch (e) {
    console.log('SKIP: the npm package candied is not installed (npm ci in ' + __dirname + ')');
    process.exit(77);
}

function parseArguments(argv) {
    const options = {emulator: []};
    for (let i = 0; i < argv.length; ++i) {
        const key = argv[i];
        if (key === '--edgetrack' || key === '--dbc' || key === '--work')
            options[key.slice(2)] = argv[++i];
        else if (key === '--emulator')
            options.emulator = argv.slice(i + 1).filter((word) => word.length > 0);
        if (key === '--emulator')
            break;
    }
    for (const required of ['edgetrack', 'dbc', 'work'])
        if (!options[required])
            throw new Error('--' + required + ' is required');
    return options;
}

function fail(message) {
    console.error('FAIL: ' + message);
    process.exit(1);
}

/** Run edgetrack (through the emulator when cross-built); resolves with its exit code. */
function runEdgetrack(options, args) {
    const command = options.emulator.length > 0 ? options.emulator[0] : options.edgetrack;
    const commandArgs =
        options.emulator.length > 0 ? [...options.emulator.slice(1), options.edgetrack, ...args] : args;
    return new Promise((resolve) => {
        const child = childProcess.spawn(command, commandArgs, {stdio: ['ignore', 'pipe', 'pipe']});
        let output = '';
        child.stdout.on('data', (data) => (output += data));
        child.stderr.on('data', (data) => (output += data));
        child.on('close', (code) => resolve({code, output}));
    });
}

/** Model files (INTERFACES §4) from a recording's truth/object_K.csv: every pair an edge. */
function writeTruthModels(recording, models) {
    fs.mkdirSync(models, {recursive: true});
    for (let k = 0; ; ++k) {
        const file = path.join(recording, 'truth', 'object_' + k + '.csv');
        if (!fs.existsSync(file))
            return k;
        const markers = fs.readFileSync(file, 'utf8').trim().split('\n').slice(1)
            .map((line) => line.split(',').slice(1).map(Number));
        const edges = [];
        for (let i = 0; i < markers.length; ++i)
            for (let j = i + 1; j < markers.length; ++j)
                edges.push([i, j, Math.hypot(...markers[i].map((v, a) => v - markers[j][a]))]);
        fs.writeFileSync(path.join(models, 'body_' + k + '.json'),
                         JSON.stringify({id: k, name: 'body ' + k, markers, edges, s_min: 4}));
    }
}

/** Bodies of one DTrack datagram: frame number and, by id, position (mm) and rotation. */
function parseDtrack(text) {
    const frame = {number: -1, bodies: new Map()};
    for (const line of text.split('\r\n')) {
        if (line.startsWith('fr '))
            frame.number = Number(line.slice(3));
        if (!line.startsWith('6d '))
            continue;
        const blocks = [...line.matchAll(/\[([^\]]*)\]/g)].map((m) => m[1].trim().split(/\s+/).map(Number));
        for (let b = 0; b + 2 < blocks.length; b += 3) {
            const r = blocks[b + 2]; // column-wise: r0 r1 r2 is the first column
            frame.bodies.set(blocks[b][0], {
                position: blocks[b + 1],
                rotation: [[r[0], r[3], r[6]], [r[1], r[4], r[7]], [r[2], r[5], r[8]]],
            });
        }
    }
    return frame;
}

/** Angle (rad) between rotation matrix R and unit quaternion q = (w, x, y, z). */
function angleBetween(R, q) {
    const [w, x, y, z] = q;
    const Q = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ];
    // M = R^T Q; atan2 of its skew part over its trace stays exact for small angles, where acos
    // of the trace alone would turn the 6 decimals of DTrack's matrix into 1e-3 rad.
    const M = [0, 1, 2].map((i) => [0, 1, 2].map((j) => R[0][i] * Q[0][j] + R[1][i] * Q[1][j] +
                                                     R[2][i] * Q[2][j]));
    const sine = Math.hypot(M[2][1] - M[1][2], M[0][2] - M[2][0], M[1][0] - M[0][1]) / 2;
    const cosine = (M[0][0] + M[1][1] + M[2][2] - 1) / 2;
    return Math.atan2(sine, cosine);
}

async function main() {
    const options = parseArguments(process.argv.slice(2));
    fs.rmSync(options.work, {recursive: true, force: true});
    fs.mkdirSync(options.work, {recursive: true});
    const recording = path.join(options.work, 'rec');
    const models = path.join(options.work, 'models');
    const log = path.join(options.work, 'can.log');

    const sim = await runEdgetrack(options, ['sim', '--scene', 'two_cubes', '--frames', '1',
                                             '--level', 'points', '--seed', '1', '--out', recording]);
    if (sim.code !== 0)
        fail('edgetrack sim: ' + sim.output);
    if (writeTruthModels(recording, models) !== 2)
        fail('expected two objects in ' + recording);

    const socket = dgram.createSocket('udp4');
    const dtrack = new Map(); // frame number -> bodies
    socket.on('message', (message) => {
        const frame = parseDtrack(message.toString('latin1'));
        dtrack.set(frame.number, frame.bodies);
    });
    await new Promise((resolve) => socket.bind(0, '127.0.0.1', resolve));
    const run = await runEdgetrack(options, [
        'run', '--board', 'sim', '--scene', 'two_cubes', '--frames', '300', '--models', models,
        '--udp', '127.0.0.1:' + socket.address().port, '--can-log', log]);
    await new Promise((resolve) => setTimeout(resolve, 200)); // the last datagrams
    socket.close();
    if (run.code !== 0)
        fail('edgetrack run: ' + run.output);

    const database = new candied.Dbc().load(fs.readFileSync(options.dbc, 'utf8'));
    const can = new candied.Can();
    can.database = database;
    // candump -L: (SECONDS.MICROSECONDS) IFACE ID#DATA for classic frames.
    const pattern = /^\((\d+)\.(\d{6})\) (\S+) ([0-9A-F]{3}|[0-9A-F]{8})#([0-9A-F]*)$/;
    const lines = fs.readFileSync(log, 'utf8').split('\n').filter((line) => line.length > 0);
    const pending = new Map(); // body -> signals decoded since its last STATUS frame
    let compared = 0;
    let worstPosition_mm = 0;
    let worstAngle_rad = 0;
    const problems = [];
    for (const line of lines) {
        const fields = pattern.exec(line);
        if (!fields)
            fail('not a classic candump -L line: ' + line);
        const id = parseInt(fields[4], 16);
        const payload = fields[5].match(/../g).map((byte) => parseInt(byte, 16));
        const message = can.decode(can.createFrame(id, payload));
        if (!message)
            fail('frame ' + fields[4] + ' is not in the DBC (or its length differs): ' + line);
        const body = Number(/^BODY(\d+)_/.exec(message.name)[1]);
        const signals = pending.get(body) || {};
        for (const [name, signal] of message.boundSignals)
            signals[name] = signal.value;
        pending.set(body, signals);
        if (!message.name.endsWith('_STATUS'))
            continue;
        pending.delete(body);
        if (signals.Found !== 1)
            continue;
        const frame = dtrack.get(signals.FrameNumber);
        if (frame === undefined)
            continue; // a datagram lost on loopback: nothing to compare with
        const pose = frame.get(body);
        if (pose === undefined) {
            problems.push('frame ' + signals.FrameNumber + ': body ' + body + ' on CAN, not in DTrack');
            continue;
        }
        if (signals.Counter !== signals.FrameNumber % 16)
            problems.push('frame ' + signals.FrameNumber + ': counter ' + signals.Counter);
        const missing = ['Counter', 'PositionX', 'PositionY', 'PositionZ', 'QuatW', 'QuatX', 'QuatY',
                         'QuatZ', 'Markers', 'FrameNumber', 'Latency']
            .filter((name) => !Number.isFinite(signals[name]));
        if (missing.length > 0) {
            problems.push('frame ' + signals.FrameNumber + ', body ' + body + ': no ' + missing.join(', '));
            continue;
        }
        const position = [signals.PositionX, signals.PositionY, signals.PositionZ];
        const q = [signals.QuatW, signals.QuatX, signals.QuatY, signals.QuatZ];
        const norm = Math.hypot(...q);
        const positionError = Math.hypot(...position.map((v, a) => v - pose.position[a]));
        const angleError = angleBetween(pose.rotation, q.map((v) => v / norm));
        worstPosition_mm = Math.max(worstPosition_mm, positionError);
        worstAngle_rad = Math.max(worstAngle_rad, angleError);
        ++compared;
    }
    // Position: 0.01 mm steps on CAN and 0.001 mm in DTrack's text, so up to 0.0055 mm per axis.
    // Quaternion: 1/16383 per component, which turns the rotation by up to about 2.5e-4 rad.
    if (!(worstPosition_mm <= Math.sqrt(3) * 0.0055))
        problems.push('position differs by ' + worstPosition_mm + ' mm');
    if (!(worstAngle_rad <= 3e-4))
        problems.push('rotation differs by ' + worstAngle_rad + ' rad');
    if (compared < 200)
        problems.push('only ' + compared + ' poses compared');
    console.log(lines.length + ' CAN frames decoded by candied; ' + compared +
                ' poses compared with DTrack: worst position ' + worstPosition_mm.toFixed(4) +
                ' mm, worst rotation ' + worstAngle_rad.toExponential(2) + ' rad');
    if (problems.length > 0)
        fail(problems.slice(0, 10).join('; '));
}

main().catch((error) => fail(error.stack || String(error)));
